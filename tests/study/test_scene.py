"""The scene of a moment: fish arrows, roles and target, the tank, and the Foxglove messages
recordings carry."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from mcap.reader import make_reader

from fishswarm.bluebot.parameters import BODY_LENGTH, Tank
from fishswarm.formations.maps import target_map
from fishswarm.protocols.codec import encode
from fishswarm.protocols.messages import Snapshot
from fishswarm.study.metrics import FormationTarget
from fishswarm.study.recording import SCENE_TOPIC, open_recorder, read_recording
from fishswarm.study.scene import (
    ROLE_RGB,
    SCENE_SCHEMA,
    Scene,
    Stage,
    scene_json_schema,
    scene_message,
    scene_of,
    tank_edges,
    upright,
    yaw_quaternion,
)


def _snapshot(position: np.ndarray, yaw: list[float], time: float = 2.0) -> Snapshot:
    count = len(yaw)
    return Snapshot(
        tick=2,
        time=time,
        ids=np.arange(count, dtype=np.int64),
        position=np.asarray(position, dtype=np.float64),
        velocity=np.zeros((count, 3)),
        yaw=np.asarray(yaw, dtype=np.float64),
        neighbors_seen=np.zeros(count, dtype=np.int64),
        broadcasts=np.zeros(count, dtype=np.int64),
    )


def test_the_tanks_twelve_edges_run_between_its_corners() -> None:
    edges = tank_edges((2.0, 1.0, 0.5))
    assert edges.shape == (12, 2, 3)
    steps = edges[:, 1] - edges[:, 0]
    # Every edge runs along one axis, from a corner towards +axis: four edges per axis.
    lengths = sorted(steps.sum(axis=1).tolist())
    assert lengths == [0.5] * 4 + [1.0] * 4 + [2.0] * 4
    assert ((steps > 0).sum(axis=1) == 1).all()
    corners = {tuple(p) for p in edges.reshape(-1, 3).tolist()}
    assert len(corners) == 8 and (0.0, 0.0, 0.0) in corners and (2.0, 1.0, 0.5) in corners


def _rotate(q: dict[str, float], v: np.ndarray) -> np.ndarray:
    """v rotated by the unit quaternion q (q v q*)."""
    w, u = q["w"], np.array([q["x"], q["y"], q["z"]])
    turned: np.ndarray = 2 * (u @ v) * u + (w * w - u @ u) * v + 2 * w * np.cross(u, v)
    return turned


def test_a_quarter_turn_left_turns_the_body_axis_from_x_to_y() -> None:
    q = yaw_quaternion(math.pi / 2)
    half = math.sqrt(0.5)
    assert q == pytest.approx({"x": 0.0, "y": 0.0, "z": half, "w": half})
    np.testing.assert_allclose(_rotate(q, np.array([1.0, 0.0, 0.0])), [0.0, 1.0, 0.0], atol=1e-12)


@given(st.floats(-10.0, 10.0))
def test_a_yaw_quaternion_turns_the_body_axis_to_the_heading(yaw: float) -> None:
    q = yaw_quaternion(yaw)
    assert sum(v * v for v in q.values()) == pytest.approx(1.0)
    turned = _rotate(q, np.array([1.0, 0.0, 0.0]))
    np.testing.assert_allclose(turned, [math.cos(yaw), math.sin(yaw), 0.0], atol=1e-9)


def test_a_fish_points_along_its_yaw_and_outside_a_formation_has_no_role() -> None:
    position = np.array([[0.1, 0.2, 0.3], [0.4, 0.5, 0.6], [0.7, 0.8, 0.9]])
    scene = scene_of(_snapshot(position, [0.0, math.pi / 2, math.pi]))
    np.testing.assert_allclose(
        scene.heading, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]], atol=1e-12
    )
    assert scene.roles == ("fish",) * 3 and scene.slots is None
    assert scene.colours().tolist() == [list(ROLE_RGB["fish"])] * 3


def test_a_formations_roles_and_target_come_from_the_positions() -> None:
    slots = target_map("pyramid", 6, spacing=0.3)
    position = slots + np.array([0.9, 0.9, 0.5])
    position[5, 1] += 0.4  # one fish far from its place
    scene = scene_of(_snapshot(position, [0.0] * 6), FormationTarget(slots, 0.3, 0.1))
    # The pyramid's apex is furthest along +x (the map's orientation): the leader.
    assert scene.roles == ("leader", "joined", "joined", "joined", "joined", "seeking")
    assert scene.slots is not None and scene.slots.shape == (6, 3)
    near = np.linalg.norm(scene.slots[:, None] - position[None], axis=2).min(axis=0)
    assert (near[:5] < 0.1).all() and near[5] > 0.2


def test_a_local_formations_scene_draws_the_sides_of_its_completed_shapes() -> None:
    jsonschema = pytest.importorskip("jsonschema")
    # Three fish in an equilateral triangle of side 0.3 and a fourth far off.
    height = 0.3 * math.sqrt(3) / 2
    position = np.array(
        [[0.5, 0.5, 0.5], [0.8, 0.5, 0.5], [0.65, 0.5 + height, 0.5], [1.5, 1.5, 0.5]]
    )
    target = FormationTarget(None, 0.3, 0.05, "triangle")
    scene = scene_of(_snapshot(position, [0.0] * 4), target)
    assert scene.roles == ("joined", "joined", "joined", "seeking")
    assert scene.slots is None and scene.edges is not None
    sides = {tuple(sorted(map(tuple, edge.round(6).tolist()))) for edge in scene.edges}
    corners = [tuple(p) for p in position[:3].round(6).tolist()]
    assert sides == {tuple(sorted((a, b))) for a, b in itertools.combinations(corners, 2)}
    data = json.loads(scene_message(scene))
    jsonschema.validate(data, scene_json_schema())
    (lines,) = next(e for e in data["entities"] if e["id"] == "shapes")["lines"]
    assert lines["type"] == 2 and len(lines["points"]) == 6


def test_a_scene_message_draws_each_fish_the_tank_and_the_landmark() -> None:
    jsonschema = pytest.importorskip("jsonschema")
    position = np.array([[0.5, 0.5, 0.2], [1.0, 0.25, 0.4]])
    scene = scene_of(_snapshot(position, [0.0, math.pi / 2], time=2.5))
    data = json.loads(scene_message(scene, Stage((1.78, 1.78, 1.17), (0.89, 0.89, 0.3))))
    jsonschema.validate(data, scene_json_schema())
    entities = {e["id"]: e for e in data["entities"]}
    assert set(entities) == {"fish", "tank", "landmark"}
    for entity in entities.values():
        assert entity["frame_id"] == "tank"
        assert entity["timestamp"] == {"sec": 2, "nsec": 500_000_000}
    arrows = entities["fish"]["arrows"]
    # Drawn upright in the 1.78 × 1.78 × 1.17-m tank: 0.2 m deep is 0.97 m above the
    # floor, 0.25 m from the y = 0 wall is 1.53 m from the far one.
    assert [a["pose"]["position"] for a in arrows] == [
        {"x": 0.5, "y": 1.28, "z": 0.97}, {"x": 1.0, "y": 1.53, "z": 0.77},
    ]  # fmt: skip
    # Five decimals kept: a quarter turn's quaternion to 1e-5 (towards +y in the tank is
    # towards −y as drawn).
    quarter = yaw_quaternion(-math.pi / 2)
    assert arrows[1]["pose"]["orientation"] == pytest.approx(quarter, abs=1e-5)
    assert arrows[0]["shaft_length"] + arrows[0]["head_length"] == pytest.approx(BODY_LENGTH)
    assert arrows[0]["color"] == pytest.approx(
        {"r": 31 / 255, "g": 119 / 255, "b": 180 / 255, "a": 1.0}, abs=1e-5
    )
    (walls,) = entities["tank"]["lines"]
    assert walls["type"] == 2 and len(walls["points"]) == 24
    (landmark,) = entities["landmark"]["spheres"]
    assert landmark["pose"]["position"] == {"x": 0.89, "y": 0.89, "z": 0.87}
    # Without a stage, the fish alone; with a formation target, its slots too.
    slots = target_map("pyramid", 2, spacing=0.3) + 0.5
    target = FormationTarget(slots, 0.3, 0.1)
    alone = json.loads(scene_message(scene_of(_snapshot(slots, [0.0, 0.0]), target)))
    assert [e["id"] for e in alone["entities"]] == ["fish", "target"]
    assert len(alone["entities"][1]["spheres"]) == 2


def test_a_recording_carries_the_scene_for_foxglove(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    position = np.array([[0.5, 0.5, 0.2]])
    update = scene_message(scene_of(_snapshot(position, [0.3])), Stage((1.0, 1.0, 1.0)))
    with open_recorder(path, {"fish": 1}) as recorder:
        recorder.snapshot(2.0, encode(_snapshot(position, [0.3])))
        recorder.scene(2.0, update)
    with path.open("rb") as stream:
        reader = make_reader(stream)
        ((schema, channel, message),) = list(reader.iter_messages(topics=[SCENE_TOPIC]))
    assert schema is not None
    assert (schema.name, schema.encoding, channel.message_encoding) == (
        SCENE_SCHEMA, "jsonschema", "json",
    )  # fmt: skip
    assert json.loads(schema.data) == scene_json_schema()
    assert message.log_time == 2_000_000_000
    assert message.data == update
    # Readers of snapshots pass over scenes.
    assert [s.ids.tolist() for s in read_recording(path).snapshots] == [[0]]


def test_every_arrow_points_along_its_fish_whatever_the_yaw() -> None:
    yaw = np.random.default_rng(5).uniform(-10.0, 10.0, 50)
    position = np.random.default_rng(6).uniform(0.0, 1.0, (50, 3))
    message = json.loads(scene_message(scene_of(_snapshot(position, yaw.tolist()))))
    arrows = message["entities"][0]["arrows"]
    for arrow, angle, xyz in zip(arrows, yaw, position, strict=True):
        turned = _rotate(arrow["pose"]["orientation"], np.array([1.0, 0.0, 0.0]))
        # Drawn upright (half a turn about x): the heading's y turns over with the tank's.
        np.testing.assert_allclose(turned, [math.cos(angle), -math.sin(angle), 0.0], atol=1e-4)
        width, height = Tank().size[1:]  # no stage: the study's tank
        drawn = [xyz[0], width - xyz[1], height - xyz[2]]
        np.testing.assert_allclose(list(arrow["pose"]["position"].values()), drawn, atol=1e-5)


def test_fish_near_the_surface_are_drawn_at_the_top_of_the_tank() -> None:
    # Depth 0.05 m and 1.10 m in a 1.17-m tank: 1.12 m and 0.07 m above the floor; the
    # walls span the floor (0) to the surface (1.17); x and y stay.
    position = np.array([[0.3, 0.4, 0.05], [0.3, 0.4, 1.10]])
    data = json.loads(
        scene_message(scene_of(_snapshot(position, [0.0, 0.0])), Stage((1.78, 1.78, 1.17)))
    )
    entities = {e["id"]: e for e in data["entities"]}
    heights = [a["pose"]["position"]["z"] for a in entities["fish"]["arrows"]]
    assert heights == pytest.approx([1.12, 0.07])
    walls = [point["z"] for point in entities["tank"]["lines"][0]["points"]]
    assert (min(walls), max(walls)) == (0.0, 1.17)
    np.testing.assert_allclose(
        upright(position, (1.78, 1.78, 1.17)), [[0.3, 1.38, 1.12], [0.3, 1.38, 0.07]]
    )


def test_the_drawn_tank_is_turned_not_mirrored() -> None:
    # A fish at the tank's centre heading +x, a neighbour to its right (+y in the tank
    # frame, whose z points down) and one below it. Drawn in a right-handed frame with z up,
    # the neighbour on the right must still be on the right, along forward × up (facing +x
    # with z up, +y is on the left and x × z = −y).
    tank = (2.0, 2.0, 1.0)
    fish = np.array([1.0, 1.0, 0.5])
    right, below = fish + np.array([0, 0.3, 0]), fish + np.array([0, 0, 0.3])
    drawn = upright(np.array([fish, right, below]), tank)
    scene = Scene(0.0, np.array([0]), fish[None], np.array([[1.0, 0.0, 0.0]]), ("fish",))
    forward = scene.upright(tank).heading[0]
    up = np.array([0.0, 0.0, 1.0])
    assert np.dot(drawn[1] - drawn[0], np.cross(forward, up)) > 0  # on the right
    assert drawn[2][2] < drawn[0][2]  # deeper is lower
    # A fish heading +y (turned right from +x) is drawn turned right from +x as well.
    turned = Scene(0.0, np.array([0]), fish[None], np.array([[0.0, 1.0, 0.0]]), ("fish",))
    assert np.cross(forward, turned.upright(tank).heading[0])[2] < 0  # clockwise from above


def test_a_scene_is_drawn_in_the_stages_own_tank_fish_slots_and_sides_alike() -> None:
    # A 3 × 2 × 1-m tank (not the study's, not square): 0.25 m from the y = 0 wall is
    # 1.75 m from the far one, 0.2 m deep is 0.8 m above the floor.
    scene = Scene(
        0.3, np.array([0]), np.array([[0.5, 0.25, 0.2]]), np.array([[1.0, 0.0, 0.0]]),
        ("joined",), slots=np.array([[1.0, 0.5, 0.4]]),
        edges=np.array([[[0.5, 0.25, 0.2], [1.0, 0.5, 0.4]]]),
    )  # fmt: skip
    data = json.loads(scene_message(scene, Stage((3.0, 2.0, 1.0))))
    entities = {e["id"]: e for e in data["entities"]}
    assert entities["fish"]["timestamp"] == {"sec": 0, "nsec": 300_000_000}
    (arrow,) = entities["fish"]["arrows"]
    assert arrow["pose"]["position"] == {"x": 0.5, "y": 1.75, "z": 0.8}
    (sphere,) = entities["target"]["spheres"]
    assert sphere["pose"]["position"] == {"x": 1.0, "y": 1.5, "z": 0.6}
    assert sphere["size"] == pytest.approx({axis: 0.5 * BODY_LENGTH for axis in "xyz"})
    (sides,) = entities["shapes"]["lines"]
    assert sides["points"] == [{"x": 0.5, "y": 1.75, "z": 0.8}, {"x": 1.0, "y": 1.5, "z": 0.6}]
    assert sides["color"] == arrow["color"]  # the sides of completed shapes: joined's colour
    walls = entities["tank"]["lines"][0]["points"]
    assert {axis: max(p[axis] for p in walls) for axis in "xyz"} == {"x": 3.0, "y": 2.0, "z": 1.0}


def test_each_role_has_its_own_colour() -> None:
    roles = ("fish", "joined", "seeking", "leader")
    scene = Scene(0.0, np.arange(4), np.zeros((4, 3)), np.tile([1.0, 0.0, 0.0], (4, 1)), roles)
    colours = scene.colours()
    assert colours.dtype == np.uint8
    assert colours.tolist() == [[31, 119, 180], [44, 160, 44], [255, 127, 14], [148, 103, 189]]


def test_an_empty_school_in_a_formation_run_has_no_roles_and_no_target() -> None:
    slots = target_map("pyramid", 3, spacing=0.3)
    scene = scene_of(_snapshot(np.zeros((0, 3)), []), FormationTarget(slots, 0.3, 0.1))
    assert scene.roles == () and scene.slots is None and scene.edges is None
    assert json.loads(scene_message(scene))["entities"][0]["arrows"] == []


def test_a_scenes_stamp_is_its_time_to_the_nearest_nanosecond() -> None:
    # 1.000000007 s is a hair below 1 000 000 007 ns as a float: rounded, not cut off.
    scene = Scene(1.000000007, np.array([0]), np.zeros((1, 3)), np.array([[1.0, 0, 0]]), ("fish",))
    stamp = json.loads(scene_message(scene))["entities"][0]["timestamp"]
    assert stamp == {"sec": 1, "nsec": 7}
