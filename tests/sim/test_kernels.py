"""The compiled kernels against the numpy references: integration, range search, sifting,
and whole runs of large swarms."""

from __future__ import annotations

import numpy as np
import pytest

from fishswarm.behaviors.core import stack_rows
from fishswarm.bluebot.dynamics import State, step
from fishswarm.bluebot.parameters import BlueBot, Tank
from fishswarm.bluebot.vision import Vision, _in_range, perceive, sift, to_body
from fishswarm.sim import kernels
from fishswarm.sim.engine import simulate_batch
from fishswarm.sim.physics import WorldParams
from fishswarm.sim.scenario import Scenario

pytest.importorskip("numba")

PAPER = BlueBot()
STUDY = BlueBot(euler_step=0.1, yaw_before_update=True, speed_dependent_drag=True)


def _random_state(rng: np.random.Generator, count: int, tank: Tank) -> State:
    position = rng.uniform(0.0, 1.0, (count, 3)) * np.asarray(tank.size)
    position[: count // 10, 0] = 0.0  # some on a wall, some about to leave through one
    return State(
        position,
        rng.uniform(-np.pi, np.pi, count),
        rng.normal(0.0, 0.05, (count, 3)),
        rng.normal(0.0, 0.2, count),
    )


@pytest.mark.parametrize("robot", [PAPER, STUDY], ids=["paper", "study-code"])
@pytest.mark.parametrize("duration", [1.0, 0.37, 0.0])
def test_the_integration_kernel_equals_the_numpy_reference(robot: BlueBot, duration: float) -> None:
    rng = np.random.default_rng(7)
    tank = Tank((3.0, 3.0, 1.17))
    for _ in range(3):
        state = _random_state(rng, 500, tank)
        fins = rng.uniform(-0.2, 1.2, (500, 4))  # out of range too: both clip
        reference = step(state, fins, duration=duration, robot=robot, tank=tank)
        compiled = kernels.step(state, fins, duration=duration, robot=robot, tank=tank)
        # Same operations in the same order: velocities to the bit; angles through the C
        # library's sine and cosine, equal to numpy's here but allowed the last bit.
        np.testing.assert_array_equal(compiled.body_velocity, reference.body_velocity)
        np.testing.assert_array_equal(compiled.yaw_rate, reference.yaw_rate)
        np.testing.assert_allclose(compiled.position, reference.position, rtol=0, atol=1e-12)
        np.testing.assert_allclose(compiled.yaw, reference.yaw, rtol=0, atol=1e-12)
        assert (compiled.position >= 0).all() and (compiled.position <= tank.size).all()
    with pytest.raises(ValueError, match="duration must be a finite non-negative time"):
        kernels.step(state, fins, duration=-1.0, robot=robot, tank=tank)


def _swarm(rng: np.random.Generator, count: int, side: float) -> tuple[np.ndarray, np.ndarray]:
    position = rng.uniform(0.0, 1.0, (count, 3)) * [side, side, 1.17]
    position[1] = position[0]  # coincident
    position[3] = position[2] + [0.5, 0.0, 0.0]  # collinear: 2, 3, 4 on a line, 3 between
    position[4] = position[2] + [1.0, 0.0, 0.0]
    yaw = rng.uniform(-np.pi, np.pi, count)
    yaw[2] = 0.0  # fish 2 faces along the line: 3 ahead, 4 behind 3
    return position, yaw


@pytest.mark.parametrize(("count", "side"), [(40, 2.0), (600, 12.0), (300, 1.0)])
def test_the_range_search_kernel_equals_the_reference(count: int, side: float) -> None:
    # 40 fish: the reference's all-pairs branch; 600: its KD-tree branch. Ties (fish 3 has
    # fish 2 and 4 both 0.5 m away; 0 and 1 coincide) go by index in all three. 40 fish
    # have fewer others in range than the kernel keeps in order as found; 300 in a metre's
    # square all the others, sorted once found (600 fish: some of each).
    position, _ = _swarm(np.random.default_rng(count), count, side)
    index, distance = _in_range(position, 3.0)
    found, gaps = kernels.in_range(position, 3.0)
    in_range = (found >= 0).sum(axis=1)
    crowded = in_range > kernels.INSERTION_MAX
    assert (crowded.all(), crowded.any()) == {
        40: (False, False),
        600: (False, True),
        300: (True, True),
    }[count]
    np.testing.assert_array_equal(found, index)
    # The all-pairs branch sums the squares with einsum: the last bit may differ.
    np.testing.assert_allclose(gaps, distance, rtol=1e-15, atol=0)
    row = found[3].tolist()
    assert row.index(4) == row.index(2) + 1  # tied at 0.5 m: the lower index first
    assert gaps[3][row.index(2)] == gaps[3][row.index(4)] == 0.5
    assert found[0][0] == 1 and gaps[0][0] == 0.0


def test_the_range_search_kernel_at_its_edges() -> None:
    # A row of fish exactly one range apart: each has its two neighbours, in every branch.
    row = np.zeros((300, 3))
    row[:, 0] = np.arange(300) * 3.0
    for position in (row, row[:40]):
        index, distance = _in_range(position, 3.0)
        found, gaps = kernels.in_range(position, 3.0)
        np.testing.assert_array_equal(found, index)
        np.testing.assert_array_equal(gaps, distance)
        assert found[1][:2].tolist() == [0, 2] and gaps[1][:2].tolist() == [3.0, 3.0]
    # No fish, one fish: nobody in range.
    for count in (0, 1):
        found, gaps = kernels.in_range(np.zeros((count, 3)), 3.0)
        assert found.shape == gaps.shape == (count, 0)
    # A tiny range over a wide tank does not ask for a column per millimetre.
    spread = np.random.default_rng(2).uniform(0.0, 1000.0, (500, 3))
    found, _ = kernels.in_range(spread, 1e-6)
    assert found.shape == (500, 0)
    # Everyone in one place: all in range at distance 0, ties by index.
    found, gaps = kernels.in_range(np.ones((250, 3)), 0.0)
    assert found[0].tolist() == list(range(1, 250)) and not gaps.any()


@pytest.mark.parametrize(
    "vision",
    [Vision(), Vision(3.0, 0.0, 0.0), Vision(3.0, 0.5, 0.3, manhattan=True), Vision(1.0, 2.5)],
    ids=["bluebot", "see-all", "wide-manhattan", "short-half-field"],
)
def test_the_sifting_kernel_sees_what_the_reference_sees(vision: Vision) -> None:
    position, yaw = _swarm(np.random.default_rng(3), 400, 8.0)
    index, distance = _in_range(position, vision.visual_range)
    reference = sift(position, yaw, index, distance, vision=vision)
    compiled = kernels.sift(position, yaw, index, distance, vision=vision)
    seen = reference[0]
    np.testing.assert_array_equal(compiled[0], seen)
    for ours, theirs in zip(compiled[1:], reference[1:], strict=True):
        np.testing.assert_array_equal(ours[seen], theirs[seen])
    whole = perceive(position, yaw, vision=vision)
    fast = perceive(position, yaw, vision=vision, kernels=kernels.CompiledVision())
    np.testing.assert_array_equal(fast.index, whole.index)
    np.testing.assert_allclose(fast.neighbors, whole.neighbors, rtol=0, atol=1e-12)
    # The collinear fish: from 2, fish 4 hides behind 3 where spheres block (with the
    # BlueBot's small spheres nothing else hides 3 in this swarm; big ones may).
    if vision.sphere_radius <= 0.065 and vision.visual_range >= 1.0:
        assert 3 in fast.index[2]
        assert (4 in fast.index[2]) == (vision.sphere_radius == 0)


def test_the_rotation_kernel_stacks_the_rows_it_rotates() -> None:
    # Rows seen anywhere in a fish's row (not only first), a fish that sees nothing, and a
    # fish seeing every row: the stack is the rotated rows the mask marks, fish after fish.
    rng = np.random.default_rng(8)
    relative = rng.normal(0.0, 1.0, (50, 7, 3))
    yaw = rng.uniform(-np.pi, np.pi, 50)
    seen = rng.random((50, 7)) < 0.4
    seen[0], seen[1] = False, True
    body, stacked = kernels.body_frame(relative, yaw, seen)
    reference = to_body(relative, yaw)
    reference[~seen] = 0.0
    np.testing.assert_allclose(body, reference, rtol=0, atol=1e-12)
    assert stacked.counts.tolist() == seen.sum(axis=1).tolist()
    assert stacked.counts[0] == 0 and stacked.counts[1] == 7
    np.testing.assert_array_equal(stacked.rows, stack_rows(body, seen))
    assert not stacked.rows.flags.writeable and not stacked.counts.flags.writeable
    empty_body, empty = kernels.body_frame(np.zeros((3, 0, 3)), np.zeros(3), seen[:3, :0])
    assert empty_body.shape == (3, 0, 3) and empty.rows.shape == (0, 3)
    assert empty.counts.tolist() == [0, 0, 0]


def test_the_rotation_kernel_refuses_shapes_that_do_not_agree() -> None:
    with pytest.raises(ValueError, match=r"relative \(B, K, 3\), seen \(B, K\) and yaw"):
        kernels.body_frame(np.zeros((3, 4, 3)), np.zeros(3), np.ones((3, 5), dtype=bool))
    with pytest.raises(ValueError, match="got"):
        kernels.body_frame(np.zeros((3, 4, 3)), np.zeros(2), np.ones((3, 4), dtype=bool))


def test_the_compiled_vision_hands_over_its_rows_stacked() -> None:
    position, yaw = _swarm(np.random.default_rng(5), 300, 6.0)
    fast = perceive(position, yaw, vision=Vision(), kernels=kernels.CompiledVision())
    assert fast.stacked is not None
    np.testing.assert_array_equal(fast.counts, fast.mask.sum(axis=1))
    np.testing.assert_array_equal(fast.stacked.rows, stack_rows(fast.neighbors, fast.mask))
    assert perceive(position, yaw, vision=Vision()).stacked is None  # the reference's


def test_large_scenarios_integrate_and_see_with_the_kernels_and_match_the_reference(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    scenario = Scenario.crowded(300, duration=5.0, seed=4, vision_noise=0.05)
    assert WorldParams.of(scenario).compiled
    assert not WorldParams.of(Scenario()).compiled  # 25 fish: the numpy reference
    compiled = simulate_batch(scenario)
    np.testing.assert_array_equal(simulate_batch(scenario).position, compiled.position)
    monkeypatch.setattr(kernels, "COMPILED_MIN_FISH", 10**9)
    assert not WorldParams.of(scenario).compiled
    reference = simulate_batch(scenario)
    np.testing.assert_allclose(compiled.position, reference.position, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(compiled.neighbors_seen, reference.neighbors_seen)
