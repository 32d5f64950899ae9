"""Whether a behaviour keeps the rules every behaviour keeps: a check for its author.

fishswarm's own behaviours are tested so in its suite; a behaviour of one's own
(docs/behaviors.md) is checked with the same rules by :func:`check_decisions`, which
``fishswarm behaviors --check NAME`` runs. On random perceptions, inboxes of signals and decision
times (seeded), over a few decisions in a row:

- a batch where no fish sees anyone (K = 0) is decided;
- a batch gives what each fish deciding alone gives, bit for bit, memory included;
- padding rows (``neighbor_mask`` false), whatever they hold, change nothing;
- the same inputs give the same outputs.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fishswarm.behaviors.core import (
    Decision,
    FishMemory,
    FishParams,
    Inbox,
    Perception,
    decide,
    inbox_of,
    take_rows,
)
from fishswarm.protocols.messages import BROADCAST_KINDS, BROADCAST_WIDTH

WIDTH = 6
"""Most neighbour rows a fish sees in the random perceptions."""


@dataclass(frozen=True)
class Conformance:
    """What :func:`check_decisions` found.

    Attributes:
        checks: what was checked, in words, in order.
        problems: (the check, what the behaviour did wrong), in words, for each check it
            failed (none: it keeps the rules).
    """

    checks: tuple[str, ...]
    problems: tuple[tuple[str, str], ...]


Check = Callable[[FishParams, int, int, np.random.Generator], str | None]


def check_decisions(
    params: FishParams, *, fish: int = 9, decisions: int = 3, seed: int = 0
) -> Conformance:
    """Check a behaviour's decisions against the rules every behaviour keeps.

    Args:
        params: the behaviour with its parameters and controller (a scenario's).
        fish: B, the batch's size (at least 2).
        decisions: how many decisions in a row each check makes.
        seed: seeds the random perceptions, inboxes and times.

    Returns:
        The checks made and the problems found; the first problem of a check ends it.
    """
    checks: tuple[tuple[str, Check], ...] = (
        ("decides a batch where no fish sees anyone", _no_one_seen),
        (
            f"a batch of {fish} gives what each fish alone gives, memory included, over "
            f"{decisions} decisions",
            _batch_is_loop,
        ),
        ("padding rows change nothing", _padding_is_ignored),
        ("the same inputs give the same outputs", _repeats),
    )
    problems: list[tuple[str, str]] = []
    for said, check in checks:
        try:
            problem = check(params, fish, decisions, np.random.default_rng(seed))
        except Exception as error:  # the behaviour's own code failed: that is the finding
            problem = f"{type(error).__name__}: {error}"
        if problem is not None:
            problems.append((said, problem))
    return Conformance(tuple(said for said, _ in checks), tuple(problems))


def random_perception(rng: np.random.Generator, count: int, time: float, width: int) -> Perception:
    """B fish that see up to ``width`` neighbours each (padding zero) and a landmark or not."""
    neighbors = rng.normal(0.0, 0.5, (count, width, 3))
    seen = rng.integers(0, width + 1, count)
    mask = np.arange(width)[None, :] < seen[:, None]
    neighbors[~mask] = 0.0
    landmarks = rng.normal(0.0, 0.6, (count, 1, 3))
    landmark_mask = rng.uniform(size=(count, 1)) < 0.8
    landmarks[~landmark_mask] = 0.0
    heading = rng.uniform(-np.pi, np.pi, count)
    depth = rng.uniform(0.2, 1.0, count)
    return Perception(
        np.full(count, time), depth, neighbors, mask, landmarks, landmark_mask, heading
    )


def random_inbox(rng: np.random.Generator, count: int) -> Inbox:
    """What B fish heard: signals, whose numbers may be anything (a formation flag's must
    make sense, and the formation behaviour refuses ones that do not)."""
    signal = BROADCAST_KINDS.index("signal")
    heard = [
        [
            (signal, rng.integers(-5, 5, BROADCAST_WIDTH), rng.normal(0.0, 0.4, 3))
            for _ in range(int(rng.integers(0, 3)))
        ]
        for _ in range(count)
    ]
    return inbox_of(heard)


def alone(perception: Perception, inbox: Inbox, row: int) -> tuple[Perception, Inbox]:
    """One fish's perception and inbox, its padding cut to what it really has."""
    seen = int(perception.neighbor_mask[row].sum())
    heard = int(inbox.mask[row].sum())
    rows = np.array([row])
    own = take_rows(perception, rows)
    own_inbox = take_rows(inbox, rows)
    return (
        dataclasses.replace(
            own, neighbors=own.neighbors[:, :seen], neighbor_mask=own.neighbor_mask[:, :seen]
        ),
        Inbox(
            own_inbox.kind[:, :heard],
            own_inbox.values[:, :heard],
            own_inbox.sender[:, :heard],
            own_inbox.mask[:, :heard],
        ),
    )


def _differs(one: Decision, other: Decision, index: int, row: int) -> str | None:
    """How fish ``index`` of one decision and fish ``row`` of another differ, in words
    (None: they are the same, bit for bit)."""
    parts = (
        ("fins", one.fins[index], other.fins[row]),
        ("LEDs", one.led[index], other.led[row]),
        ("broadcast", one.outbox.values[index], other.outbox.values[row]),
        ("broadcast kind", one.outbox.kind[index], other.outbox.kind[row]),
        ("broadcast sent", one.outbox.mask[index], other.outbox.mask[row]),
    )
    for name, mine, theirs in parts:
        if not np.array_equal(mine, theirs):
            return f"its {name} {np.asarray(mine).tolist()} against {np.asarray(theirs).tolist()}"
    return None


def _no_one_seen(
    params: FishParams, fish: int, decisions: int, rng: np.random.Generator
) -> str | None:
    memory = FishMemory.fresh(params, fish)
    for step in range(decisions):
        perception = random_perception(rng, fish, 1.0 + step, 0)
        memory, _ = decide(memory, perception, Inbox.empty(fish), params=params)
    return None


def _batch_is_loop(
    params: FishParams, fish: int, decisions: int, rng: np.random.Generator
) -> str | None:
    batch = FishMemory.fresh(params, fish)
    singles = [FishMemory.fresh(params, 1) for _ in range(fish)]
    for step in range(decisions):
        # Jittered decision times: controllers that integrate see uneven periods.
        perception = random_perception(rng, fish, 1.0 + step + rng.uniform(-0.2, 0.2), WIDTH)
        inbox = random_inbox(rng, fish)
        batch, decision = decide(batch, perception, inbox, params=params)
        for row in range(fish):
            own, own_inbox = alone(perception, inbox, row)
            singles[row], single = decide(singles[row], own, own_inbox, params=params)
            wrong = _differs(single, decision, 0, row)
            if wrong is not None:
                return f"at decision {step + 1}, fish {row} alone gives {wrong} in the batch"
    return None


def _padding_is_ignored(
    params: FishParams, fish: int, decisions: int, rng: np.random.Generator
) -> str | None:
    plain = FishMemory.fresh(params, fish)
    padded = FishMemory.fresh(params, fish)
    for step in range(decisions):
        perception = random_perception(rng, fish, 1.0 + step, WIDTH)
        inbox = random_inbox(rng, fish)
        # Three more rows each, masked out, holding what padding is never promised to hold.
        extra = rng.normal(0.0, 3.0, (fish, 3, 3))
        wide = dataclasses.replace(
            perception,
            neighbors=np.concatenate([perception.neighbors, extra], axis=1),
            neighbor_mask=np.concatenate(
                [perception.neighbor_mask, np.zeros((fish, 3), dtype=bool)], axis=1
            ),
        )
        plain, decision = decide(plain, perception, inbox, params=params)
        padded, with_padding = decide(padded, wide, inbox, params=params)
        for row in range(fish):
            wrong = _differs(with_padding, decision, row, row)
            if wrong is not None:
                return (
                    f"at decision {step + 1}, fish {row} with three more padding rows gives "
                    f"{wrong} without"
                )
    return None


def _repeats(params: FishParams, fish: int, decisions: int, rng: np.random.Generator) -> str | None:
    first = FishMemory.fresh(params, fish)
    again = FishMemory.fresh(params, fish)
    for step in range(decisions):
        perception = random_perception(rng, fish, 1.0 + step, WIDTH)
        inbox = random_inbox(rng, fish)
        first, decision = decide(first, perception, inbox, params=params)
        again, repeated = decide(again, perception, inbox, params=params)
        for row in range(fish):
            wrong = _differs(repeated, decision, row, row)
            if wrong is not None:
                return f"at decision {step + 1}, fish {row} gives {wrong} the first time"
    return None
