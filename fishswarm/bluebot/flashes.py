"""Formation flags by light: a BlueBot flashes its LEDs to say it holds its place, and tells
which of the neighbours it sees are flashing.

DESIGN §2: on robots the channel is physical. A robot whose fish has joined its formation
flashes its LEDs at :data:`~fishswarm.bluebot.parameters.LED_FLASH_FREQUENCY` (15 Hz, as the
research code flashed them, SPEC §6), half of each period lit. Its neighbours take each
camera's image twice, half a flash period apart (:data:`FRAME_GAP`: two frame periods of the
60-fps camera, :data:`FRAMES_APART`): a steady light is lit in both frames, a flashing one in
exactly one of them. So a neighbour seen in only one of the two
frames flashes, and it is where that frame shows it — the flag comes situated, as a simulated
channel's delivery does.

The light says one thing only, "I hold my place": not the slot, the hops from the leader, the
effort or a swap request that a simulated channel's flag carries. A neighbour missed in one
frame by noise looks like a flasher; ``tests/bluebot/test_flashes.py`` measures how often on
rendered images. Pure numpy: this runs on the robot.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from fishswarm.bluebot.parameters import CAMERA_FRAME_RATE, LED_FLASH_FREQUENCY

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]

FRAME_GAP = 0.5 / LED_FLASH_FREQUENCY
"""Time between the two frames a camera takes each control period, s: half a flash period,
so that a flashing LED is lit in exactly one of them."""
FRAMES_APART = round(FRAME_GAP * CAMERA_FRAME_RATE)
"""The camera's frames between those two: they are the first and the last of this many + 1
consecutive frames (2 at 60 fps: 33 ms)."""
MATCH_FRACTION = 0.15
"""Two sightings are one neighbour when they lie closer than this fraction of its range (at
least :data:`MATCH_FLOOR`): as the LED pipeline merges its two cameras' sightings."""
MATCH_FLOOR = 0.05
"""The least distance within which two sightings are one neighbour, m."""


def match_sightings(
    first: FloatArray, second: FloatArray, *, fraction: float = MATCH_FRACTION
) -> tuple[IntArray, IntArray]:
    """Which sightings in two lists are the same neighbour, nearest first.

    Each sighting of ``first`` in turn takes the nearest sighting of ``second`` not yet
    taken that lies within ``fraction`` of its range (at least :data:`MATCH_FLOOR`).

    Args:
        first: (K, 3) body-frame positions, m.
        second: (L, 3) body-frame positions, m.
        fraction: how close two sightings of one neighbour lie, as a fraction of its range.

    Returns:
        (P,) rows of ``first`` and (P,) rows of ``second``, pair by pair.
    """
    rows: list[int] = []
    partners: list[int] = []
    if first.shape[0] and second.shape[0]:
        gap = np.linalg.norm(first[:, None, :] - second[None, :, :], axis=2)
        reach = np.maximum(MATCH_FLOOR, fraction * np.linalg.norm(first, axis=1))
        free = np.ones(second.shape[0], dtype=bool)
        for row in range(first.shape[0]):
            candidates = np.flatnonzero((gap[row] <= reach[row]) & free)
            if candidates.size:
                partner = int(candidates[np.argmin(gap[row, candidates])])
                rows.append(row)
                partners.append(partner)
                free[partner] = False
    return np.array(rows, dtype=np.int64), np.array(partners, dtype=np.int64)


def merge_frames(
    first: FloatArray, second: FloatArray, *, fraction: float = MATCH_FRACTION
) -> tuple[FloatArray, BoolArray]:
    """The neighbours seen in two frames taken half a flash period apart, and which flash.

    Args:
        first: (K, 3) body-frame neighbour positions found in the first frames, m.
        second: (L, 3) those found in the second frames, FRAME_GAP later, m.
        fraction: how close two sightings of one neighbour lie, as a fraction of its range.

    Returns:
        (M, 3) neighbours, near to far — one for each seen in both frames (the mean of its
        two sightings), and each seen in one frame only, where it was seen — and (M,)
        whether each flashes (seen in one frame only).
    """
    rows, partners = match_sightings(first, second, fraction=fraction)
    alone_first = np.ones(first.shape[0], dtype=bool)
    alone_first[rows] = False
    alone_second = np.ones(second.shape[0], dtype=bool)
    alone_second[partners] = False
    both = (first[rows] + second[partners]) / 2
    merged = np.concatenate([both, first[alone_first], second[alone_second]]).reshape(-1, 3)
    alone = int(alone_first.sum() + alone_second.sum())
    flashing = np.concatenate([np.zeros(rows.size, dtype=bool), np.ones(alone, dtype=bool)])
    order = np.argsort(np.linalg.norm(merged, axis=1), kind="stable")
    return merged[order], flashing[order]


def lit_at(time: float, phase: FloatArray, *, frequency: float = LED_FLASH_FREQUENCY) -> BoolArray:
    """Whether flashing LEDs are lit at ``time``: each lit for the first half of its period.

    Args:
        time: when, s.
        phase: (N,) where each flasher's period starts, as a fraction of the period in [0, 1).
        frequency: the flash rate, Hz.

    Returns:
        (N,) whether each is lit.
    """
    lit: BoolArray = np.mod(time * frequency - phase, 1.0) < 0.5
    return lit
