"""The replica network and the Elman classifier, evaluated for a whole population at once.

Parameter vectors are flat (what CMA-ES searches); the layouts are fixed here:

- replica (21 numbers): W1 (3×2), b1 (3), W2 (3×3), b2 (3); logistic units everywhere.
- classifier (5F + 36 numbers, then its radii): W_in (5×F), W_context (5×5), b_hidden (5),
  w_out (5), b_out (1). The hidden layer sees this step's inputs and its own previous state
  (the Elman memory layer); the output after the last step is the judgement.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

REPLICA_INPUTS, REPLICA_HIDDEN, REPLICA_OUTPUTS = 2, 3, 3
REPLICA_SIZE = (
    REPLICA_HIDDEN * REPLICA_INPUTS
    + REPLICA_HIDDEN
    + REPLICA_OUTPUTS * REPLICA_HIDDEN
    + REPLICA_OUTPUTS
)
CLASSIFIER_HIDDEN = 5


def logistic(x: FloatArray) -> FloatArray:
    """1 / (1 + e^−x); for x below about −709, e^−x overflows to inf and the result is 0.

    Plain numpy, not scipy's ``expit``: a replica runs on a robot, which has no scipy
    (DESIGN §7); the two differ in the last bit for about 2 % of inputs.
    """
    with np.errstate(over="ignore"):
        result: FloatArray = 1.0 / (1.0 + np.exp(-x))
    return result


def replica_outputs(weights: FloatArray, inputs: FloatArray) -> FloatArray:
    """Outputs of M replica networks.

    Args:
        weights: (M, 21).
        inputs: (M, …, 2), model m's inputs go through network m.

    Returns:
        (M, …, 3) logistic outputs.
    """
    count = weights.shape[0]
    at = 0

    def take(rows: int, columns: int) -> FloatArray:
        nonlocal at
        size = rows * columns
        block = weights[:, at : at + size].reshape(count, rows, columns)
        at += size
        return block

    w1 = take(REPLICA_HIDDEN, REPLICA_INPUTS)
    b1 = take(1, REPLICA_HIDDEN)[:, 0]
    w2 = take(REPLICA_OUTPUTS, REPLICA_HIDDEN)
    b2 = take(1, REPLICA_OUTPUTS)[:, 0]
    flat = inputs.reshape(count, -1, REPLICA_INPUTS)
    hidden = logistic(np.einsum("mhi,mki->mkh", w1, flat) + b1[:, None, :])
    output = logistic(np.einsum("moh,mkh->mko", w2, hidden) + b2[:, None, :])
    return output.reshape(*inputs.shape[:-1], REPLICA_OUTPUTS)


def classifier_size(features: int) -> int:
    """Number of network parameters of a classifier with ``features`` inputs."""
    hidden = CLASSIFIER_HIDDEN
    return hidden * features + hidden * hidden + hidden + hidden + 1


def classify(parameters: FloatArray, shared: FloatArray, own: FloatArray) -> FloatArray:
    """Run C Elman classifiers over the same S tracks.

    Args:
        parameters: (C, classifier_size(K + R)) network parameters (radii excluded).
        shared: (S, T, K) inputs every classifier sees alike (speed, angular speed).
        own: (C, S, T, R) inputs that depend on the classifier (counts within its radii).

    Returns:
        (C, S) output after the last step, in (0, 1): near 1 means "ideal fish".
    """
    count = parameters.shape[0]
    samples, steps, shared_inputs = shared.shape
    inputs = shared_inputs + own.shape[-1]
    hidden = CLASSIFIER_HIDDEN
    at = 0

    def take(size: int) -> FloatArray:
        nonlocal at
        block = parameters[:, at : at + size]
        at += size
        return block

    w_in = take(hidden * inputs).reshape(count, hidden, inputs)
    w_context = take(hidden * hidden).reshape(count, hidden, hidden)
    b_hidden = take(hidden)
    w_out = take(hidden)
    b_out = take(1)
    # Batched matrix products (BLAS) rather than einsum: x @ Wᵀ per classifier.
    context_t = w_context.transpose(0, 2, 1)
    shared_t = w_in[:, :, :shared_inputs].transpose(0, 2, 1)
    own_t = w_in[:, :, shared_inputs:].transpose(0, 2, 1)
    state = np.zeros((count, samples, hidden))
    for step in range(steps):
        drive = state @ context_t
        if shared_inputs:
            drive += shared[None, :, step] @ shared_t
        if own.shape[-1]:
            drive += own[:, :, step] @ own_t
        drive += b_hidden[:, None, :]
        state = logistic(drive)
    result: FloatArray = logistic(np.einsum("csh,ch->cs", state, w_out) + b_out)
    return result
