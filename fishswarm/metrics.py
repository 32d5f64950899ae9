"""Swarm metrics on positions: the three mean distances of SPEC.md §3 and neighbours seen."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree
from scipy.spatial.distance import pdist

FloatArray = NDArray[np.float64]

METRIC_NAMES = ("centroid_distance", "pairwise_distance", "nearest_neighbor_distance")


def centroid_distance(position: FloatArray) -> float:
    """Distance of each fish to the centroid of the others, averaged over fish, m.

    What the research code printed as "mean inter-robot distance".
    """
    count = position.shape[0]
    if count < 2:
        return 0.0
    others = (position.sum(axis=0)[None, :] - position) / (count - 1)
    return float(np.linalg.norm(position - others, axis=1).mean())


def pairwise_distance(position: FloatArray) -> float:
    """Mean distance over all pairs of fish, m."""
    if position.shape[0] < 2:
        return 0.0
    return float(pdist(position).mean())


def nearest_neighbor_distance(position: FloatArray) -> float:
    """Distance of each fish to its nearest other fish, averaged over fish, m."""
    if position.shape[0] < 2:
        return 0.0
    distance, _ = cKDTree(position).query(position, k=2)
    return float(distance[:, 1].mean())


def swarm_metrics(position: FloatArray, neighbors_seen: NDArray[np.int64]) -> dict[str, float]:
    """All metrics of one snapshot: the three distances (m) and mean neighbours seen."""
    return {
        "centroid_distance": centroid_distance(position),
        "pairwise_distance": pairwise_distance(position),
        "nearest_neighbor_distance": nearest_neighbor_distance(position),
        "neighbors_seen": float(neighbors_seen.mean()) if neighbors_seen.size else 0.0,
    }


ORBIT_METRIC_NAMES = ("radius", "revolutions", "speed", "collisions")


def orbit_metrics(
    position: FloatArray, *, centre: FloatArray | None, period: float, contact: float
) -> FloatArray:
    """Metrics of orbiting fish at every tick, from their positions.

    Args:
        position: (T, N, 3) positions, m.
        centre: (3,) the orbit centre, m; None for fish orbiting each other (waltz), whose
            centre is their barycentre at each tick.
        period: time between ticks, s.
        contact: two fish closer than this collide, m (one body length).

    Returns:
        (T, 4) columns: mean planar distance to the centre (m); revolutions so far (mean over
        fish of the unwrapped angle around the centre / 2π, positive in the direction the
        fish orbit: clockwise in overhead plots); mean planar speed over the last period
        (m/s, 0 at the first tick); colliding pairs.
    """
    steps, count = position.shape[:2]
    middle = (
        position.mean(axis=1, keepdims=True)
        if centre is None
        else np.broadcast_to(np.asarray(centre, dtype=np.float64), (steps, 1, 3))
    )
    offset = position[..., :2] - middle[..., :2]
    radius = np.hypot(offset[..., 0], offset[..., 1]).mean(axis=1)
    angle = np.unwrap(np.arctan2(offset[..., 1], offset[..., 0]), axis=0)
    # The fish keep the centre on their left with z down: clockwise in overhead plots (y up),
    # the direction of decreasing atan2(y, x); counted positive.
    revolutions = ((angle[0] - angle) / (2 * np.pi)).mean(axis=1)
    speed = np.zeros(steps)
    if steps > 1:
        moved = np.hypot(*np.moveaxis(np.diff(position[..., :2], axis=0), -1, 0))
        speed[1:] = moved.mean(axis=1) / period
    collisions = np.zeros(steps)
    if count > 1:
        for tick in range(steps):
            collisions[tick] = float((pdist(position[tick]) < contact).sum())
    return np.stack([radius, revolutions, speed, collisions], axis=1)
