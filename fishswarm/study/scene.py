"""What a swarm looks like at one moment in 3-D: the fish, their roles, the target, the tank.

One description for every viewer: the live view in the browser (:mod:`.live_view`) draws it,
and recordings carry it as Foxglove ``SceneUpdate`` messages (JSON), so that a run opens in
Foxglove or Lichtblick as it does in ``fishswarm view``.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fishswarm.bluebot.parameters import BODY_LENGTH, Tank
from fishswarm.protocols.messages import Snapshot
from fishswarm.sim.scenario import Scenario
from fishswarm.study.metrics import FormationTarget

FloatArray = NDArray[np.float64]

ROLE_RGB = {
    "fish": (31, 119, 180),
    "joined": (44, 160, 44),
    "seeking": (255, 127, 14),
    "leader": (148, 103, 189),
}
"""Each role's colour (8-bit RGB): any fish outside a formation, a formation fish in its
place, one still seeking it, the leader (matplotlib's tab palette, as in the figures)."""

TARGET_RGB = (150, 150, 150)
"""The colour of a formation's target slots (8-bit RGB)."""

LANDMARK_RGB = (214, 39, 40)
"""The colour of the landmark (8-bit RGB)."""

WALL_RGB = (128, 128, 128)
"""The colour of the tank's edges (8-bit RGB)."""

SCENE_SCHEMA = "foxglove.SceneUpdate"
"""The schema name under which Foxglove and Lichtblick recognise a scene."""

FRAME = "tank"
"""The frame every scene entity is drawn in: the tank frame turned upright (x as in the tank
frame, y from the far wall, z up from the floor; the tank frame's z is depth, down: see
:func:`upright`)."""


@dataclass(frozen=True)
class Stage:
    """What does not move: the tank and the landmark.

    Attributes:
        tank: tank size (x, y, z), m; the tank spans from the origin to it.
        landmark: the landmark's position (x, y, z), m, or None.
    """

    tank: tuple[float, float, float]
    landmark: tuple[float, float, float] | None = None


def stage_of(scenario: Scenario) -> Stage:
    """The tank and landmark of a run."""
    return Stage(scenario.tank, scenario.landmark)


@dataclass(frozen=True)
class Scene:
    """The swarm at one moment.

    Attributes:
        time: simulated time, s.
        ids: (N,) fish ids.
        position: (N, 3) positions in the tank frame, m.
        heading: (N, 3) unit vectors along each fish's body, in the tank frame.
        roles: (N,) each fish's role, a key of :data:`ROLE_RGB`.
        slots: (M, 3) a global formation's target laid onto the school, m, or None.
        edges: (E, 2, 3) the sides of a local formation's completed shapes, each from one
            fish to another, m, or None.
    """

    time: float
    ids: NDArray[np.int64]
    position: FloatArray
    heading: FloatArray
    roles: tuple[str, ...]
    slots: FloatArray | None = None
    edges: FloatArray | None = None

    def upright(self, tank: Sequence[float]) -> Scene:
        """The scene as drawn in a tank of size ``tank`` (x, y, z), m: its positions, slots,
        shapes' sides and headings turned upright (:func:`upright`)."""
        heading = np.array(self.heading, dtype=np.float64)
        heading[:, 1:] *= -1.0
        return dataclasses.replace(
            self,
            position=upright(self.position, tank),
            heading=heading,
            slots=None if self.slots is None else upright(self.slots, tank),
            edges=None if self.edges is None else upright(self.edges, tank),
        )

    def colours(self) -> NDArray[np.uint8]:
        """(N, 3) each fish's colour by its role, 8-bit RGB."""
        table = np.array([ROLE_RGB[role] for role in self.roles], dtype=np.uint8)
        return table.reshape(len(self.roles), 3)


def role_names(joined: NDArray[np.bool_], leader: NDArray[np.bool_]) -> tuple[str, ...]:
    """(N,) each formation fish's role: the leader, in its place (joined) or seeking."""
    return tuple(
        "leader" if lead else "joined" if inside else "seeking"
        for inside, lead in zip(joined.tolist(), leader.tolist(), strict=True)
    )


def scene_of(snapshot: Snapshot, formation: FormationTarget | None = None) -> Scene:
    """The scene of a snapshot; in a formation run, the fish's roles (as
    :meth:`FormationTarget.roles` sees them from the positions) and the fitted target, or
    the sides of the completed local shapes."""
    yaw = snapshot.yaw
    heading = np.stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)], axis=1)
    count = int(snapshot.ids.size)
    roles: tuple[str, ...] = ("fish",) * count
    slots = edges = None
    if formation is not None and count:
        found = formation.roles(snapshot.position)
        roles = role_names(found.joined, found.leader)
        slots = found.slots
        if formation.local_shape is not None:
            edges = snapshot.position[found.edges]
    return Scene(snapshot.time, snapshot.ids, snapshot.position, heading, roles, slots, edges)


def upright(points: Any, tank: Sequence[float]) -> FloatArray:
    """(..., 3) points of the tank frame (right-handed, z: depth below the surface, down)
    as drawn in a tank of size ``tank`` (x, y, z), m, in a viewer's right-handed frame with z
    up: turned half a turn about the x axis, so x stays, y = width − y and z = height −
    depth. Fish near the surface are drawn at the top, as in the side views of ``plot`` and
    ``animate``, and a fish turning right is seen turning right (turning z alone over would
    draw the tank's mirror image)."""
    drawn = np.array(points, dtype=np.float64)
    drawn[..., 1] = tank[1] - drawn[..., 1]
    drawn[..., 2] = tank[2] - drawn[..., 2]
    return drawn


def tank_edges(tank: tuple[float, float, float]) -> FloatArray:
    """(12, 2, 3) the tank's edges, each from one corner to another, m."""
    x, y, z = tank
    corners = np.array(
        [[i * x, j * y, k * z] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=np.float64
    )
    # Corners differ in one coordinate along an edge: their indices differ in one bit.
    pairs = [(a, a | bit) for a in range(8) for bit in (1, 2, 4) if not a & bit]
    return np.stack([corners[[a, b]] for a, b in pairs])


def yaw_quaternion(yaw: float) -> dict[str, float]:
    """The rotation by ``yaw`` (rad) about z as a unit quaternion, Foxglove's field names."""
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}


DIGITS = 5
"""Decimals kept in scene messages: 10 µm, and 1e-5 of a quaternion or colour channel (the
messages are JSON; every digit is a byte in the recording)."""


def _stamp(time: float) -> dict[str, int]:
    nanoseconds = round(time * 1e9)
    return {"sec": nanoseconds // 1_000_000_000, "nsec": nanoseconds % 1_000_000_000}


def _colour(rgb: tuple[int, int, int], alpha: float = 1.0) -> dict[str, float]:
    r, g, b = (round(channel / 255, DIGITS) for channel in rgb)
    return {"r": r, "g": g, "b": b, "a": alpha}


def _point(xyz: Any) -> dict[str, float]:
    return {"x": round(float(xyz[0]), DIGITS), "y": round(float(xyz[1]), DIGITS),
            "z": round(float(xyz[2]), DIGITS)}  # fmt: skip


def _pose(xyz: Any, yaw: float = 0.0) -> dict[str, Any]:
    turn = {k: round(v, DIGITS) for k, v in yaw_quaternion(yaw).items()}
    return {"position": _point(xyz), "orientation": turn}


def _entity(name: str, time: float, **primitives: list[dict[str, Any]]) -> dict[str, Any]:
    return {
        "timestamp": _stamp(time),
        "frame_id": FRAME,
        "id": name,
        "lifetime": {"sec": 0, "nsec": 0},  # until replaced
        "frame_locked": False,
        "metadata": [],
        **primitives,
    }


def _fish_arrows(scene: Scene) -> str:
    """The JSON of one arrow per fish, written row by row from a template (a dict and
    ``json.dumps`` per fish took 20 ms a snapshot at 1 000 fish; this takes a tenth)."""
    dimensions = json.dumps(
        {
            "shaft_length": 0.6 * BODY_LENGTH,
            "shaft_diameter": 0.15 * BODY_LENGTH,
            "head_length": 0.4 * BODY_LENGTH,
            "head_diameter": 0.35 * BODY_LENGTH,
        },
        separators=(",", ":"),
    )[1:-1]
    colours = {
        role: json.dumps(_colour(rgb), separators=(",", ":")) for role, rgb in ROLE_RGB.items()
    }
    half_yaw = np.arctan2(scene.heading[:, 1], scene.heading[:, 0]) / 2
    rows = np.column_stack([scene.position, np.sin(half_yaw), np.cos(half_yaw)]).round(DIGITS)
    return ",".join(
        f'{{"pose":{{"position":{{"x":{x!r},"y":{y!r},"z":{z!r}}},"orientation":'
        f'{{"x":0.0,"y":0.0,"z":{qz!r},"w":{qw!r}}}}},{dimensions},"color":{colours[role]}}}'
        for (x, y, z, qz, qw), role in zip(rows.tolist(), scene.roles, strict=True)
    )


def scene_message(scene: Scene, stage: Stage | None = None) -> bytes:
    """A Foxglove ``SceneUpdate`` (JSON) drawing ``scene``: an arrow a body length long per
    fish (tail at the fish, pointing along its body, coloured by role), the fitted target's
    slots as translucent spheres or the sides of completed local shapes as lines, and with
    ``stage`` the tank's edges and the landmark.

    Each entity keeps its id from message to message, so every message replaces the last.
    Everything is drawn upright (:func:`upright`) in the stage's tank (without a stage, the
    study's)."""
    tank = stage.tank if stage is not None else Tank().size
    scene = scene.upright(tank)
    entities: list[dict[str, Any]] = []
    if scene.slots is not None:
        size = {"x": 0.5 * BODY_LENGTH, "y": 0.5 * BODY_LENGTH, "z": 0.5 * BODY_LENGTH}
        spheres = [
            {"pose": _pose(xyz), "size": size, "color": _colour(TARGET_RGB, 0.5)}
            for xyz in scene.slots
        ]
        entities.append(_entity("target", scene.time, spheres=spheres))
    if scene.edges is not None:
        sides = {
            "type": 2,  # LINE_LIST: each pair of points one segment
            "pose": _pose((0.0, 0.0, 0.0)),
            "thickness": 0.004,
            "scale_invariant": False,
            "points": [_point(xyz) for edge in scene.edges for xyz in edge],
            "color": _colour(ROLE_RGB["joined"]),
            "colors": [],
            "indices": [],
        }
        entities.append(_entity("shapes", scene.time, lines=[sides]))
    if stage is not None:
        points = [_point(xyz) for edge in tank_edges(stage.tank) for xyz in edge]
        line = {
            "type": 2,  # LINE_LIST: each pair of points one segment
            "pose": _pose((0.0, 0.0, 0.0)),
            "thickness": 0.005,
            "scale_invariant": False,
            "points": points,
            "color": _colour(WALL_RGB),
            "colors": [],
            "indices": [],
        }
        entities.append(_entity("tank", scene.time, lines=[line]))
        if stage.landmark is not None:
            size = {"x": 0.04, "y": 0.04, "z": 0.04}
            landmark = {
                "pose": _pose(upright(stage.landmark, tank)),
                "size": size,
                "color": _colour(LANDMARK_RGB),
            }
            entities.append(_entity("landmark", scene.time, spheres=[landmark]))
    # The fish entity with an empty arrow list, its arrows spliced in as text.
    fish = json.dumps(_entity("fish", scene.time, arrows=[]), separators=(",", ":"))
    texts = [fish.replace('"arrows":[]', f'"arrows":[{_fish_arrows(scene)}]')]
    texts += [json.dumps(entity, separators=(",", ":")) for entity in entities]
    return f'{{"deletions":[],"entities":[{",".join(texts)}]}}'.encode()


def _object(**properties: Any) -> dict[str, Any]:
    return {"type": "object", "properties": properties}


def _array(items: dict[str, Any]) -> dict[str, Any]:
    return {"type": "array", "items": items}


def scene_json_schema() -> dict[str, Any]:
    """The JSON schema of the scene messages: the parts of Foxglove's ``SceneUpdate`` that
    fishswarm writes (field names and meanings as Foxglove defines them)."""
    number = {"type": "number"}
    integer = {"type": "integer"}
    vector = _object(x=number, y=number, z=number)
    pose = _object(position=vector, orientation=_object(x=number, y=number, z=number, w=number))
    colour = _object(r=number, g=number, b=number, a=number)
    time = _object(sec=integer, nsec=integer)
    arrow = _object(
        pose=pose, shaft_length=number, shaft_diameter=number, head_length=number,
        head_diameter=number, color=colour,
    )  # fmt: skip
    sphere = _object(pose=pose, size=vector, color=colour)
    line = _object(
        type=integer, pose=pose, thickness=number, scale_invariant={"type": "boolean"},
        points=_array(vector), color=colour, colors=_array(colour), indices=_array(integer),
    )  # fmt: skip
    entity = _object(
        timestamp=time, frame_id={"type": "string"}, id={"type": "string"}, lifetime=time,
        frame_locked={"type": "boolean"}, metadata=_array(_object()),
        arrows=_array(arrow), spheres=_array(sphere), lines=_array(line),
    )  # fmt: skip
    return {
        "title": SCENE_SCHEMA,
        **_object(
            deletions=_array(_object(timestamp=time, type=integer, id={"type": "string"})),
            entities=_array(entity),
        ),
    }
