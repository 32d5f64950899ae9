"""The study's rules: who leads, where a global map is anchored, which slot or spot a fish
takes (SPEC §5). Pure and batched over fish, in each fish's body frame.

- **Leader**: of a fish and the neighbours it sees, the one furthest along the intended
  orientation; the map is anchored at it, its x axis along the orientation.
- **Rank**: a fish ranks itself among what it sees by the same projection and wants the slot
  of its rank.
- **Conflict**: a slot (or a local shape's spot) is skipped when it is occupied — a
  neighbour within ``tolerance`` of it, or a neighbour that flagged it as its own — or when
  the fish's rival is nearer to it than the fish: its nearest neighbour that holds no place
  (for a local shape, its nearest neighbour outside the shape); the fish takes the next one.
  When a rival is nearer to every free slot, the fish takes the first free one all the same
  (the rival may be bound elsewhere); with no free slot it stays where it is.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]

STAY = -1
"""The choice of a fish that finds no spot: it stays."""


def formation_axes(orientation: FloatArray) -> FloatArray:
    """(B, 3, 3) the formation frame's axes in each fish's body frame, as rows: x along the
    horizontal part of ``orientation`` (B, 3), y to its right, z down."""
    forward = orientation.astype(np.float64).copy()
    forward[:, 2] = 0.0
    length = np.linalg.norm(forward, axis=1)
    forward = np.where(
        (length > 0)[:, None], forward / np.where(length > 0, length, 1.0)[:, None], [1.0, 0, 0]
    )
    down = np.tile([0.0, 0.0, 1.0], (forward.shape[0], 1))
    right = np.cross(down, forward)
    return np.stack([forward, right, down], axis=1)


def leader_and_rank(
    neighbors: FloatArray, mask: BoolArray, orientation: FloatArray
) -> tuple[FloatArray, IntArray]:
    """Where each fish's leader is (B, 3, the fish itself at the origin if it leads) and the
    fish's own rank (B,) among itself and the neighbours it sees (0: it leads).

    Ties go to the neighbour first in the list; a fish ranks behind neighbours level with it,
    and so takes the first of them for its leader (leading itself only when it ranks 0).
    """
    axes = formation_axes(orientation)
    ahead = np.einsum("bkd,bd->bk", neighbors, axes[:, 0])
    ahead = np.where(mask, ahead, -np.inf)
    count = neighbors.shape[0]
    if neighbors.shape[1] == 0:
        return np.zeros((count, 3)), np.zeros(count, dtype=np.int64)
    best = np.argmax(ahead, axis=1)
    best_value = ahead[np.arange(count), best]
    leads = best_value < 0.0
    leader = np.where(leads[:, None], 0.0, neighbors[np.arange(count), best])
    rank: IntArray = (ahead >= 0.0).sum(axis=1).astype(np.int64)
    return leader, rank


def place_map(leader: FloatArray, orientation: FloatArray, slots: FloatArray) -> FloatArray:
    """(B, N, 3) a map's slots (N, 3, formation frame) anchored at each fish's leader and
    turned to the orientation, in each fish's body frame."""
    axes = formation_axes(orientation)
    placed: FloatArray = leader[:, None, :] + np.einsum("nf,bfd->bnd", slots, axes)
    return placed


def nearest_only(
    neighbors: FloatArray, mask: BoolArray, *, skip: int = 0, settled: BoolArray | None = None
) -> BoolArray:
    """(B, K) marks each fish's nearest visible neighbour after its ``skip`` nearest — the
    one the study's conflict rule compares with (for a local shape, the nearest that is not
    part of the shape) — leaving out ``settled`` neighbours (B, K), which hold a place of
    their own and compete for no other."""
    candidates = mask if settled is None else mask & ~settled
    distance = np.where(candidates, np.einsum("bkd,bkd->bk", neighbors, neighbors), np.inf)
    order = np.argsort(np.argsort(distance, axis=1, kind="stable"), axis=1, kind="stable")
    marked: BoolArray = candidates & (order == skip)
    return marked


def choose_spot(
    spots: FloatArray,
    valid: BoolArray,
    neighbors: FloatArray,
    mask: BoolArray,
    *,
    tolerance: float,
    rivals: BoolArray | None = None,
    claimed: BoolArray | None = None,
    first: IntArray | None = None,
    preference: FloatArray | None = None,
    share: bool = False,
) -> IntArray:
    """The spot each fish takes, by the study's conflict rule (:data:`STAY` if none).

    Args:
        spots: (B, S, 3) candidate spots in the body frame, m.
        valid: (B, S) which spots exist.
        neighbors: (B, K, 3) visible neighbours in the body frame, m.
        mask: (B, K) which rows are real.
        tolerance: a neighbour this close to a spot occupies it, m.
        rivals: (B, K) the neighbours that compete for the spots (a neighbour nearer to a
            spot than the fish takes it); None: every visible neighbour. The neighbours a
            local shape is built on are not rivals.
        claimed: (B, S) spots that a neighbour flagged as its own.
        share: share the free spots out at once (nearest pairs first) instead of the study's
            order; see below.
        first: (B,) the spot to try first (a global map: the fish's rank); spots are tried
            from there on in order, then from the first. None: by ``preference``.
        preference: (B, S) spots are tried in increasing order of this (a local shape:
            groups of neighbours in turn); None: nearest spot first, then by distance.

    Returns:
        (B,) the index of the chosen spot, or STAY.
    """
    count, options = spots.shape[:2]
    own = np.linalg.norm(spots, axis=2)  # the fish is at the origin of its body frame
    if neighbors.shape[1]:
        gaps = np.linalg.norm(spots[:, :, None, :] - neighbors[:, None, :, :], axis=3)
        closest = np.where(mask[:, None, :], gaps, np.inf).min(axis=2)
        competing = mask if rivals is None else mask & rivals
        rival = np.where(competing[:, None, :], gaps, np.inf).min(axis=2)
    else:
        closest = rival = np.full((count, options), np.inf)
    free = valid & (closest > tolerance)
    if claimed is not None:
        free &= ~claimed
    usable = free & (rival >= own)
    if first is None:
        key = own if preference is None else preference
        order = np.argsort(np.where(valid, key, np.inf), axis=1, kind="stable")
    else:
        order = (first[:, None] + np.arange(options)[None, :]) % max(options, 1)
    rows = np.arange(count)[:, None]
    if not options:
        return np.full(count, STAY, dtype=np.int64)
    in_order = usable[rows, order]
    found = in_order.any(axis=1) & (not share)
    pick = np.argmax(in_order, axis=1)
    chosen: IntArray = np.where(found, order[np.arange(count), pick], STAY).astype(np.int64)
    # Where a rival is nearer to every free spot, the fish shares the free spots out among
    # itself and the neighbours that hold none, nearest pairs first, and takes its share.
    blocked = np.flatnonzero(~found & free.any(axis=1))
    for fish in blocked.tolist():
        seekers = mask[fish] & ~(
            np.linalg.norm(spots[fish][:, None, :] - neighbors[fish][None, :, :], axis=2)
            <= tolerance
        ).any(axis=0)
        chosen[fish] = _greedy_share(spots[fish], free[fish], neighbors[fish][seekers])
    return chosen


def _greedy_share(spots: FloatArray, free: BoolArray, others: FloatArray) -> int:
    """The spot a fish (at the origin) gets when free spots go to the nearest seekers
    first: the fish and ``others`` (M, 3); STAY if every free spot goes to someone else."""
    seekers = np.concatenate([np.zeros((1, 3)), others])
    gaps = np.linalg.norm(seekers[:, None, :] - spots[None, :, :], axis=2)
    gaps[:, ~free] = np.inf
    taken_spot = np.zeros(spots.shape[0], dtype=np.bool_)
    done = np.zeros(seekers.shape[0], dtype=np.bool_)
    for flat in np.argsort(gaps, axis=None, kind="stable").tolist():
        seeker, spot = divmod(flat, spots.shape[0])
        if not np.isfinite(gaps[seeker, spot]):
            break
        if done[seeker] or taken_spot[spot]:
            continue
        if seeker == 0:
            return int(spot)
        done[seeker], taken_spot[spot] = True, True
    return STAY
