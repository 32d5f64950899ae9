"""Replica and classifier forward passes against hand-written loops."""

from __future__ import annotations

import math

import numpy as np

from fishswarm.learning.networks import (
    REPLICA_SIZE,
    classifier_size,
    classify,
    replica_outputs,
)


def _sigmoid(x: float) -> float:
    return 1.0 / (1.0 + math.exp(-x))


def test_replica_matches_a_loop() -> None:
    rng = np.random.default_rng(2)
    weights = rng.normal(0, 1, (3, REPLICA_SIZE))
    inputs = rng.normal(0, 1, (3, 4, 2))
    out = replica_outputs(weights, inputs)
    for m in range(3):
        w = weights[m]
        w1, b1 = w[:6].reshape(3, 2), w[6:9]
        w2, b2 = w[9:18].reshape(3, 3), w[18:21]
        for k in range(4):
            hidden = [_sigmoid(float(w1[h] @ inputs[m, k] + b1[h])) for h in range(3)]
            expected = [_sigmoid(float(w2[o] @ np.array(hidden) + b2[o])) for o in range(3)]
            np.testing.assert_allclose(out[m, k], expected, rtol=1e-12)


def test_elman_classifier_matches_a_loop() -> None:
    rng = np.random.default_rng(3)
    classifiers, samples, steps, shared_inputs, own_inputs = 2, 3, 4, 2, 1
    inputs = shared_inputs + own_inputs
    parameters = rng.normal(0, 1, (classifiers, classifier_size(inputs)))
    shared = rng.uniform(0, 1, (samples, steps, shared_inputs))
    own = rng.uniform(0, 1, (classifiers, samples, steps, own_inputs))
    out = classify(parameters, shared, own)
    for c in range(classifiers):
        p = parameters[c]
        w_in = p[: 5 * inputs].reshape(5, inputs)
        w_context = p[5 * inputs : 5 * inputs + 25].reshape(5, 5)
        b_hidden = p[5 * inputs + 25 : 5 * inputs + 30]
        w_out, b_out = p[5 * inputs + 30 : 5 * inputs + 35], p[-1]
        for s in range(samples):
            state = np.zeros(5)
            for t in range(steps):
                x = np.concatenate([shared[s, t], own[c, s, t]])
                state = np.array(
                    [
                        _sigmoid(float(w_in[h] @ x + w_context[h] @ state + b_hidden[h]))
                        for h in range(5)
                    ]
                )
            expected = _sigmoid(float(w_out @ state + b_out))
            assert out[c, s] == np.float64(expected) or abs(out[c, s] - expected) < 1e-12
