"""Formation metrics on drawn cases: the study's fitness, shape error, lattice energy."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fishswarm.formations.maps import target_map
from fishswarm.formations.metrics import collisions, deviation_energy, fish_fitness, shape_error


def test_fitness_of_three_fish_drawn_on_paper() -> None:
    # Targets at x = 0, 1, 2; fish A on target 0, fish B 0.3 from target 1, fish C 0.05
    # from A (crowding radius 0.1, tolerance 0.2).
    targets = np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]])
    fish = np.array([[0.0, 0, 0], [1.3, 0, 0], [0.05, 0, 0]])
    fitness = fish_fitness(fish, targets, tolerance=0.2, crowding_radius=0.1)
    # A: crowded by C (0.2); target 0 is occupied by C (within 0.2) → nearest free is
    #    target 1 (1.0): F = 1.2. B: not crowded; target 1 is free (0.3): F = 0.3.
    # C: crowded by A (0.2); target 0 is occupied by A → target 1 at 0.95: F = 1.15.
    np.testing.assert_allclose(fitness, [1.2, 0.3, 1.15])
    # One target, held by the second fish: the first finds none free, D = the tolerance;
    # the second sits on it, D = 0.
    held = np.array([[5.0, 0, 0], [0.0, 0, 0]])
    lone = fish_fitness(held, targets[:1], tolerance=0.2, crowding_radius=0.1)
    np.testing.assert_allclose(lone, [0.2, 0.0])


def test_shape_error_ignores_a_rigid_motion_and_the_order_of_the_fish() -> None:
    target = target_map("pyramid", 10, spacing=0.3)
    turn = math.radians(70)
    rotation = np.array(
        [[math.cos(turn), math.sin(turn), 0], [-math.sin(turn), math.cos(turn), 0], [0, 0, 1]]
    )
    fish = (target @ rotation + [0.8, 0.5, 0.4])[np.random.default_rng(1).permutation(10)]
    rms, joined = shape_error(fish, target, tolerance=0.075)
    assert rms == pytest.approx(0.0, abs=1e-9) and joined == 1.0
    # One fish 0.2 m off its slot: the error is at most 0.2/√10 (the alignment may share it).
    fish[3] += [0.0, 0.0, 0.2]
    rms, joined = shape_error(fish, target, tolerance=0.075)
    assert 0.0 < rms <= 0.2 / math.sqrt(10) + 1e-12
    assert joined == pytest.approx(0.9)


def test_lattice_energy_and_collisions() -> None:
    lattice = target_map("pyramid", 10, spacing=0.3)
    assert deviation_energy(lattice, spacing=0.3) == pytest.approx(0.0, abs=1e-20)
    stretched = lattice * 1.1
    assert deviation_energy(stretched, spacing=0.3) == pytest.approx(0.01)  # 10 % off
    assert deviation_energy(lattice * 10, spacing=0.3) == 1.0
    assert collisions(np.array([[0.0, 0, 0], [0.1, 0, 0], [0.5, 0, 0]])) == 1  # 0.1 < 0.13


def test_alignment_lays_a_drawn_triangle_onto_fish_that_hold_it_turned_and_shuffled() -> None:
    from fishswarm.formations.metrics import align

    # Target: a right triangle (0,0), (0.4,0), (0,0.3). The fish hold it turned by 90°
    # anticlockwise and shifted to (1, 1): (1,1), (1,1.4), (0.7,1); listed in another order.
    target = np.array([[0.0, 0, 0], [0.4, 0, 0], [0.0, 0.3, 0]])
    fish = np.array([[0.7, 1.0, 0.5], [1.0, 1.0, 0.5], [1.0, 1.4, 0.5]])
    fit = align(fish, target)
    assert fit.slot_of.tolist() == [2, 0, 1]
    np.testing.assert_allclose(fit.slots[fit.slot_of], fish, atol=1e-9)
    np.testing.assert_allclose(fit.gaps, 0.0, atol=1e-9)
    # One fish 0.1 m off its place along z: the best fit splits the miss over the three
    # (the plane may tilt and shift), and only a tolerance below the miss leaves it out.
    off = fish + np.array([[0.0, 0, 0], [0.0, 0, 0.1], [0.0, 0, 0]])
    fit = align(off, target)
    assert 0.0 < fit.rms < 0.1 / math.sqrt(3) + 1e-12
    assert fit.joined(0.1).all() and not fit.joined(1e-6).all()
    with pytest.raises(ValueError, match="3 fish against a target of 2 slots"):
        align(fish, target[:2])
