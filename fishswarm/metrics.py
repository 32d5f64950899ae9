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
