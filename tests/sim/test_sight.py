"""Simulated fish seeing through rendered camera images (``vision_model = "camera"``)."""

from __future__ import annotations

import numpy as np
import pytest

from fishswarm.bluebot.vision import Perceived, Vision, perceive, to_body
from fishswarm.sim.physics import WorldParams
from fishswarm.sim.scenario import ConfigError, Scenario
from fishswarm.sim.sight import (
    Cameras,
    SightCounts,
    _match,
    perceive_through_cameras,
    score_sight,
)
from fishswarm.sim.tick import WorldSim

CAMERAS = Cameras()


def rngs(count: int, seed: int = 0) -> list[np.random.Generator]:
    return [np.random.default_rng([seed, fish]) for fish in range(count)]


def test_two_fish_find_each_other_within_two_percent() -> None:
    position = np.array([[0.6, 0.6, 0.5], [1.4, 1.1, 0.4]])
    yaw = np.array([0.3, 2.0])
    seen = perceive_through_cameras(position, yaw, cameras=CAMERAS, rngs=rngs(2))
    assert seen.counts.tolist() == [1, 1]
    assert seen.index.tolist() == [[1], [0]]
    truth = to_body((position[::-1] - position)[:, None, :], yaw)[:, 0, :]
    range_error = np.linalg.norm(seen.neighbors[:, 0] - truth, axis=1) / np.linalg.norm(
        truth, axis=1
    )
    assert np.all(range_error < 0.02)


def test_a_fish_alone_sees_nothing() -> None:
    seen = perceive_through_cameras(
        np.array([[1.0, 1.0, 0.5]]), np.zeros(1), cameras=CAMERAS, rngs=rngs(1)
    )
    assert seen.neighbors.shape == (1, 0, 3) and seen.counts.tolist() == [0]


def test_each_fish_draws_only_on_its_own_stream() -> None:
    rng = np.random.default_rng(4)
    position = rng.uniform(0.2, 1.0, (6, 3))
    yaw = rng.uniform(-np.pi, np.pi, 6)
    first = perceive_through_cameras(position, yaw, cameras=CAMERAS, rngs=rngs(6))
    again = perceive_through_cameras(position, yaw, cameras=CAMERAS, rngs=rngs(6))
    np.testing.assert_array_equal(first.neighbors, again.neighbors)
    # Fish 5 alone, with its own stream in the same state, sees what it saw in the swarm.
    streams = rngs(6)
    for fish in range(5):
        streams[fish] = np.random.default_rng(99 + fish)
    other = perceive_through_cameras(position, yaw, cameras=CAMERAS, rngs=streams)
    np.testing.assert_array_equal(other.neighbors[5], first.neighbors[5])


def test_score_counts_found_missed_and_false_detections_by_hand() -> None:
    # Three fish on a line 1 m apart; fish 0 truly sees 1 and 2, fish 1 sees 0 and 2.
    position = np.array([[0.0, 0.0, 0.5], [1.0, 0.0, 0.5], [2.0, 0.0, 0.5]])
    truth = Perceived(
        np.zeros((3, 2, 3)),
        np.array([[True, True], [True, True], [False, False]]),
        np.array([[1, 2], [0, 2], [-1, -1]]),
    )
    # Fish 0 found fish 1 at 1.1 m (10 % long) and a false one; fish 1 found fish 0 exactly.
    neighbors = np.zeros((3, 2, 3))
    neighbors[0, 0] = (1.1, 0.0, 0.0)
    neighbors[0, 1] = (0.0, 0.4, 0.0)
    neighbors[1, 0] = (1.0, 0.0, 0.0)
    camera = Perceived(
        neighbors,
        np.array([[True, True], [True, False], [False, False]]),
        np.array([[1, -1], [0, -1], [-1, -1]]),
    )
    counts = score_sight(camera, truth, position)
    assert (counts.visible, counts.found, counts.detected, counts.false) == (4, 2, 3, 1)
    assert counts.range_error == pytest.approx(0.1)
    summary = counts.summary()
    assert summary["recall"] == 0.5
    assert summary["false_rate"] == pytest.approx(1 / 3)
    assert summary["mean_range_error"] == pytest.approx(0.05)
    assert SightCounts().summary()["recall"] is None


def test_a_detection_is_of_the_nearest_fish_only_when_close_enough_to_it() -> None:
    # Viewer 0 at the origin facing +x; fish 1 1 m ahead, fish 2 0.1 m to the right. A
    # detection belongs to the nearest fish within 0.3 of its range (at least 0.05 m):
    # 0.3 m around fish 1, 0.05 m around fish 2.
    position = np.array([[0.0, 0.0, 0.5], [1.0, 0.0, 0.5], [0.0, 0.1, 0.5]])
    detections = np.array(
        [[[1.0, 0.25, 0.0], [1.0, -0.4, 0.0], [0.04, 0.1, 0.0], [0.0, 0.16, 0.0]]]
    )
    neighbors = np.zeros((3, 4, 3))
    neighbors[0] = detections[0]
    mask = np.zeros((3, 4), dtype=np.bool_)
    mask[0] = True
    index = _match(position, np.zeros(3), neighbors, mask)
    assert index[0].tolist() == [1, -1, 2, -1]
    assert (index[1:] == -1).all()  # no detections there


def test_the_range_error_is_relative_to_the_true_range() -> None:
    # A fish 2 m away detected at 2.2 m: 10 % off, as a fish 1 m away detected at 1.1 m.
    position = np.array([[0.0, 0.0, 0.5], [2.0, 0.0, 0.5]])
    truth = Perceived(np.zeros((2, 1, 3)), np.array([[True], [False]]), np.array([[1], [-1]]))
    neighbors = np.zeros((2, 1, 3))
    neighbors[0, 0] = (2.2, 0.0, 0.0)
    camera = Perceived(neighbors, np.array([[True], [False]]), np.array([[1], [-1]]))
    assert score_sight(camera, truth, position).range_error == pytest.approx(0.1)


def test_the_world_scores_camera_vision_against_the_geometric_model() -> None:
    scenario = Scenario(fish=6, vision_model="camera", spawn_region="tank", seed=3)
    world = WorldSim(WorldParams.of(scenario))
    world.join(list(range(6)))
    perceived = world.sense()
    truth = perceive(world.state.position, world.state.yaw, vision=Vision())
    assert world.sight.visible == int(truth.mask.sum())
    assert world.sight.detected == int(perceived.mask.sum())
    assert 0 < world.sight.found <= world.sight.visible
    geometric = WorldSim(WorldParams.of(scenario.replace(vision_model="geometric")))
    geometric.join(list(range(6)))
    geometric.sense()
    assert geometric.sight == SightCounts()


def test_an_unknown_vision_model_is_refused_with_the_choices() -> None:
    with pytest.raises(ConfigError, match="vision_model must be one of geometric, camera"):
        Scenario(vision_model="sonar")


def test_camera_vision_is_scored_against_the_noise_free_model_when_noise_is_set() -> None:
    noisy = Scenario(fish=5, vision_model="camera", vision_noise=0.05, spawn_region="tank")
    world = WorldSim(WorldParams.of(noisy))
    world.join(list(range(5)))
    world.sense()
    exact = perceive(world.state.position, world.state.yaw, vision=Vision())
    assert world.sight.visible == int(exact.mask.sum())


def test_the_world_adds_up_its_sight_scores_over_every_look() -> None:
    scenario = Scenario(fish=6, vision_model="camera", spawn_region="tank", seed=3)
    world = WorldSim(WorldParams.of(scenario))
    world.join(list(range(6)))
    world.sense()
    once = world.sight
    world.sense()  # nobody moved: the same fish are there to be seen
    truth = perceive(world.state.position, world.state.yaw, vision=Vision())
    assert once.visible == int(truth.mask.sum()) > 0
    assert world.sight.visible == 2 * once.visible
    assert world.sight.found >= once.found > 0
