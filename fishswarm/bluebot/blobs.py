"""Bright blobs in a camera image: where the LEDs of other robots (and their mirror images)
light up the blue channel.

Each lit pixel climbs to the brightest lit pixel it can reach; the peaks reached split the
lit pixels into blobs, and two peaks are joined when the light between them stays bright
(a saturated or noisy spot stays one blob; two LEDs far away, a few pixels apart, stay two).
Pure numpy: this runs on the robot.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

_OFFSETS = tuple((dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1))


@dataclass(frozen=True)
class Blobs:
    """Bright blobs in one image.

    Attributes:
        centroids: (M, 2) brightness-weighted (row, column), px.
        peaks: (M,) the brightest value in each blob.
        sizes: (M,) pixels in each blob.
        fluxes: (M,) the sum of each blob's values.
    """

    centroids: FloatArray
    peaks: FloatArray
    sizes: IntArray
    fluxes: FloatArray


def find_blobs(blue: NDArray[np.uint8], *, threshold: int, saddle_ratio: float) -> Blobs:
    """The bright blobs of one colour channel.

    Args:
        blue: (H, W) the channel, 0–255.
        threshold: pixels above this value are lit.
        saddle_ratio: peaks joined by light at or above this fraction of the fainter one are
            one blob.
    """
    height, width = blue.shape
    rows, columns = np.nonzero(blue > threshold)
    count = rows.size
    if count == 0:
        return Blobs(np.zeros((0, 2)), np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros(0))
    value = blue[rows, columns].astype(np.int64)
    where = np.full((height + 2, width + 2), -1, dtype=np.int64)
    where[rows + 1, columns + 1] = np.arange(count)
    # Neighbour k of every lit pixel (−1 where unlit), 8-connected, self included.
    neighbours = np.stack([where[rows + 1 + dr, columns + 1 + dc] for dr, dc in _OFFSETS], axis=1)
    # Climb: each pixel points to its brightest lit neighbour; ties go to the larger flat
    # index, so a saturated plateau drains to one pixel.
    key = value * (height * width) + rows * width + columns
    neighbour_key = np.where(neighbours >= 0, key[np.maximum(neighbours, 0)], -1)
    pointer = neighbours[np.arange(count), np.argmax(neighbour_key, axis=1)]
    while True:
        jumped = pointer[pointer]
        if np.array_equal(jumped, pointer):
            break
        pointer = jumped
    peaks, label = np.unique(pointer, return_inverse=True)
    label = _merge_shallow_saddles(neighbours, label, value, value[peaks], saddle_ratio)
    _, label = np.unique(label, return_inverse=True)
    blobs = int(label.max()) + 1
    weight = value.astype(np.float64)
    total = np.bincount(label, weight, blobs)
    centroids = (
        np.stack(
            [np.bincount(label, weight * rows, blobs), np.bincount(label, weight * columns, blobs)],
            axis=1,
        )
        / total[:, None]
    )
    brightest = np.zeros(blobs)
    np.maximum.at(brightest, label, weight)
    sizes = np.bincount(label, minlength=blobs).astype(np.int64)
    return Blobs(centroids, brightest, sizes, total.astype(np.float64))


def _merge_shallow_saddles(
    neighbours: IntArray, label: IntArray, value: IntArray, peak: IntArray, ratio: float
) -> IntArray:
    """Join regions whose peaks are separated by light at or above ``ratio`` × the fainter."""
    here = np.repeat(np.arange(label.size), neighbours.shape[1])
    there = neighbours.ravel()
    touching = (there >= 0) & (label[here] != label[np.maximum(there, 0)])
    if not touching.any():
        return label
    a, b = label[here[touching]], label[there[touching]]
    saddle = np.minimum(value[here[touching]], value[there[touching]])
    parent = list(range(peak.size))

    def root(node: int) -> int:
        while parent[node] != node:
            parent[node] = parent[parent[node]]
            node = parent[node]
        return node

    # Highest saddles first, so each merge compares against the peaks as they stand.
    for index in np.argsort(-saddle, kind="stable"):
        first, second = root(int(a[index])), root(int(b[index]))
        if first != second and saddle[index] >= ratio * min(peak[first], peak[second]):
            brighter, fainter = (first, second) if peak[first] >= peak[second] else (second, first)
            parent[fainter] = brighter
    return np.array([root(int(node)) for node in label], dtype=np.int64)
