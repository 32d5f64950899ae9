"""Addressing perceptions: one message per school, one per fish on its own keys.

What the world computed for a tick (vision, landmarks, inbox counts, as arrays over the live
fish) is cut into the messages each fish actor expects. Pure: the world puts what this
returns. A school so large that its batch would pass the row limit every message is held
to (:data:`~fishswarm.protocols.checks.MAX_ROWS`, against oversize input from outside) gets
its batch in consecutive parts; a school decides each part as it comes, and since a batch
decides exactly as a loop of single fish, the parts give the whole's commands.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fishswarm.bluebot.vision import Perceived
from fishswarm.protocols.checks import MAX_ROWS
from fishswarm.protocols.keys import KeySpace
from fishswarm.protocols.messages import Message, Perception, PerceptionBatch


def perception_messages(
    keys: KeySpace,
    *,
    ids: NDArray[np.int64],
    school_of: Mapping[int, str | None],
    depth: NDArray[np.float64],
    perceived: Perceived,
    landmarks: Perceived,
    inbox_counts: NDArray[np.int64],
    tick: int,
    time: float,
    run: int = 0,
    heading: NDArray[np.float64] | None = None,
    formation: str | None = None,
    rows: Sequence[int] | None = None,
    row_limit: int = MAX_ROWS,
) -> list[tuple[str, Message]]:
    """The perception messages of the fish at ``rows`` (default all) for one tick.

    Args:
        keys: the swarm's key space.
        ids: (N,) the live fish, ascending.
        school_of: each fish's school, or None for a fish on its own keys.
        depth: (N,) each fish's depth, m.
        perceived: what each fish sees of the others (padded, compact rows).
        landmarks: which landmarks each fish sees.
        inbox_counts: (N,) deliveries each fish waits for.
        tick: the tick (the event number in jitter mode).
        time: simulated time, s.
        run: the world's run id.
        heading: (N,) each fish's compass heading, rad (None: no compass).
        formation: the formation fish are told to take (None: as configured).
        rows: indices into ``ids`` of the fish to address.
        row_limit: most fish, neighbour rows or landmark rows one batch may carry.

    Returns:
        (key, message) pairs: a :class:`Perception` per fish on its own keys, then a
        :class:`PerceptionBatch` per school (several parts, fish in order, where one would
        pass ``row_limit``), schools in name order.
    """
    messages: list[tuple[str, Message]] = []
    schools: dict[str, list[int]] = {}
    fish_ids = ids.tolist()
    for row in range(len(fish_ids)) if rows is None else rows:
        fish_id = fish_ids[row]
        school = school_of.get(fish_id)
        if school is not None:
            schools.setdefault(school, []).append(row)
            continue
        perception = Perception(
            fish_id,
            tick,
            time,
            float(depth[row]),
            perceived.neighbors[row, : perceived.counts[row]],
            landmarks.neighbors[row][landmarks.mask[row]],
            int(inbox_counts[row]),
            run,
            None if heading is None else float(heading[row]),
            formation,
        )
        messages.append((keys.perception(fish_id), perception))
    for school, school_rows in sorted(schools.items()):
        everyone = np.array(school_rows, dtype=np.intp)
        sizes = np.maximum(perceived.counts[everyone], landmarks.counts[everyone])
        for members in _parts(everyone, sizes, row_limit):
            messages.append(
                (
                    keys.school_perceptions(school),
                    _batch(
                        members,
                        ids=ids,
                        depth=depth,
                        perceived=perceived,
                        landmarks=landmarks,
                        inbox_counts=inbox_counts,
                        tick=tick,
                        time=time,
                        run=run,
                        heading=heading,
                        formation=formation,
                    ),
                )
            )
    return messages


def _parts(
    members: NDArray[np.intp], sizes: NDArray[np.int64], limit: int
) -> list[NDArray[np.intp]]:
    """Consecutive runs of ``members`` whose fish and rows (``sizes`` each) stay within
    ``limit``; one fish alone is never split (a fish's own rows are far below the limit)."""
    if members.size <= limit and int(sizes.sum()) <= limit:
        return [members]  # the usual case: one batch, without a loop over the fish
    parts: list[NDArray[np.intp]] = []
    start, total = 0, 0
    for index, size in enumerate(sizes.tolist()):
        if index > start and (total + size > limit or index - start >= limit):
            parts.append(members[start:index])
            start, total = index, 0
        total += size
    parts.append(members[start:])
    return parts


def _batch(
    members: NDArray[np.intp],
    *,
    ids: NDArray[np.int64],
    depth: NDArray[np.float64],
    perceived: Perceived,
    landmarks: Perceived,
    inbox_counts: NDArray[np.int64],
    tick: int,
    time: float,
    run: int,
    heading: NDArray[np.float64] | None,
    formation: str | None,
) -> PerceptionBatch:
    """The perception batch of some fish of a school."""
    counts = perceived.counts[members]
    seen = np.arange(perceived.neighbors.shape[1]) < counts[:, None]
    return PerceptionBatch(
        tick,
        time,
        ids[members],
        depth[members],
        counts,
        perceived.neighbors[members][seen],
        landmarks.counts[members],
        landmarks.neighbors[members][landmarks.mask[members]],
        inbox_counts[members],
        run,
        None if heading is None else heading[members],
        formation,
    )
