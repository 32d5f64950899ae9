"""Blobs in the blue channel: spots apart stay apart, a saturated noisy spot is one."""

from __future__ import annotations

import numpy as np

from fishswarm.bluebot.blobs import find_blobs


def spots(centres: list[tuple[float, float]], peak: float, sigma: float = 0.5) -> np.ndarray:
    """A 40×40 blue channel with Gaussian spots, over a level of 10."""
    rows, columns = np.mgrid[0:40, 0:40]
    light = np.zeros((40, 40))
    for row, column in centres:
        light += peak * np.exp(-((rows - row) ** 2 + (columns - column) ** 2) / (2 * sigma**2))
    return np.clip(np.rint(10 + light), 0, 255).astype(np.uint8)


def test_two_spots_three_pixels_apart_are_two_blobs_at_their_centres() -> None:
    blobs = find_blobs(spots([(10.0, 20.0), (13.0, 20.0)], 200.0), threshold=40, saddle_ratio=0.7)
    order = np.argsort(blobs.centroids[:, 0])
    np.testing.assert_allclose(blobs.centroids[order], [[10.0, 20.0], [13.0, 20.0]], atol=0.05)


def test_a_saturated_noisy_spot_is_one_blob() -> None:
    image = spots([(20.0, 20.0)], 5000.0, sigma=1.5).astype(np.int64)
    image += np.random.default_rng(0).integers(-3, 4, image.shape)
    blobs = find_blobs(np.clip(image, 0, 255).astype(np.uint8), threshold=40, saddle_ratio=0.7)
    assert blobs.centroids.shape == (1, 2)
    np.testing.assert_allclose(blobs.centroids[0], [20.0, 20.0], atol=0.1)
    assert blobs.peaks[0] == 255 and blobs.sizes[0] > 20


def test_a_dark_image_has_no_blobs() -> None:
    blobs = find_blobs(np.full((30, 40), 39, dtype=np.uint8), threshold=40, saddle_ratio=0.7)
    assert blobs.centroids.shape == (0, 2) and blobs.fluxes.size == 0


def test_a_pixel_at_the_threshold_is_not_lit() -> None:
    row = np.array([[0, 40, 0, 0, 41, 0]], dtype=np.uint8)
    blobs = find_blobs(row, threshold=40, saddle_ratio=0.5)
    np.testing.assert_array_equal(blobs.centroids, [[0.0, 4.0]])


def test_peaks_joined_exactly_at_the_saddle_ratio_are_one_blob() -> None:
    # Peaks 200 and 100 with 50 between: 50 is half the fainter, the ratio itself.
    row = np.array([[200, 50, 100]], dtype=np.uint8)
    assert find_blobs(row, threshold=10, saddle_ratio=0.5).sizes.tolist() == [3]
    assert find_blobs(row, threshold=10, saddle_ratio=0.51).sizes.tolist() == [2, 1]


def test_a_merged_blob_is_judged_by_its_brightest_peak() -> None:
    """Peaks A 200, B 100 and C 150 in a row, A–B joined at 70 and B–C at 60. A and B merge
    first (70 ≥ 0.5 × 100); the merged blob's peak is A's 200, so C joins only at
    0.5 × min(200, 150) = 75 or more: 60 keeps it apart (judged by B's 100 it would join)."""
    row = np.array([[200, 70, 100, 60, 150]], dtype=np.uint8)
    blobs = find_blobs(row, threshold=10, saddle_ratio=0.5)
    assert blobs.sizes.tolist() == [3, 2]
    assert blobs.peaks.tolist() == [200.0, 150.0]
