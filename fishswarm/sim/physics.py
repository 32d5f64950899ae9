"""The simulated world's parameters, compiled once from a scenario, and its pure steps:
place fish, see, move.

This is the physics and vision the world actor and the batch engine wrap (like Gymnasium's
pure ``FuncEnv`` with thin stateful wrappers). A scenario is read once into
:class:`WorldParams`; nothing re-reads it tick by tick.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from fishswarm.bluebot.dynamics import State, rest_state, step
from fishswarm.bluebot.parameters import BlueBot, Tank
from fishswarm.bluebot.vision import Perceived, Vision, perceive, perceive_landmarks
from fishswarm.sim import kernels
from fishswarm.sim.scenario import Scenario
from fishswarm.sim.sight import Cameras, perceive_through_cameras
from fishswarm.sim.streams import Stream, stream
from fishswarm.sim.wake import WAKE_LENGTH, WAKE_WIDTH, wake_shelter

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass(frozen=True)
class WorldParams:
    """What the world needs of a scenario, read once.

    Attributes:
        seed: master seed of every random stream.
        tank: the tank.
        vision: the vision model.
        cameras: with camera vision, the cameras and LED pipeline every fish sees through
            (None: the geometric vision model).
        landmarks: (L, 3) fixed landmarks in the tank frame, m (the orbit centre first).
        control_period: nominal time between decisions, s.
        ticks: snapshots after the first (the run's length in control periods).
        time_mode: ``lockstep``, ``jitter`` or ``realtime``.
        jitter: s.d. of a fish's control period in jitter mode, s.
        spawn_region: ``ball`` or ``tank``.
        spawn_radius: radius of the ``ball`` fish start in, m.
        channel_range: how far a broadcast carries, m.
        channel_loss: probability that one delivery is lost.
        flag_sight: the vision by which formation flags travel (by light: to the fish that
            see their sender), or None (within ``channel_range``).
        one_bit_flags: formation flags say only "I hold my place" (:mod:`fishswarm.sim.medium`).
        switch_formation: a formation the fish are told to switch to, or None.
        switch_at: when, s.
        robot: the BlueBot's parameters.
        still_until: fish are held still until this time, s (the study code's start delay;
            0 by default).
        flow: the water's velocity in the tank frame, m/s.
        wake_saving, wake_length, wake_width: the wake model (:mod:`fishswarm.sim.wake`;
            saving 0: none).
        compiled: integrate with the compiled kernel (:mod:`fishswarm.sim.kernels`): chosen
            from the scenario's size, so every process of a run integrates alike.
    """

    seed: int
    tank: Tank
    vision: Vision
    cameras: Cameras | None
    landmarks: FloatArray
    control_period: float
    ticks: int
    time_mode: str
    jitter: float
    spawn_region: str
    spawn_radius: float
    channel_range: float
    channel_loss: float
    flag_sight: Vision | None = None
    one_bit_flags: bool = False
    switch_formation: str | None = None
    switch_at: float = 0.0
    robot: BlueBot = BlueBot()
    still_until: float = 0.0
    compiled: bool = False
    flow: tuple[float, float, float] = (0.0, 0.0, 0.0)
    wake_saving: float = 0.0
    wake_length: float = WAKE_LENGTH
    wake_width: float = WAKE_WIDTH

    @classmethod
    def of(cls, scenario: Scenario) -> WorldParams:
        """The world parameters of ``scenario``."""
        return cls(
            seed=scenario.seed,
            tank=scenario.the_tank(),
            vision=scenario.vision(),
            cameras=Cameras() if scenario.vision_model == "camera" else None,
            landmarks=scenario.landmarks(),
            control_period=scenario.control_period,
            ticks=scenario.ticks,
            time_mode=scenario.time_mode,
            jitter=scenario.jitter,
            spawn_region=scenario.spawn_region,
            spawn_radius=scenario.resolved_spawn_radius(),
            channel_range=scenario.channel_range,
            channel_loss=scenario.channel_loss,
            flag_sight=scenario.flag_sight,
            one_bit_flags=scenario.one_bit_flags,
            switch_formation=scenario.switch_formation,
            switch_at=scenario.switch_at,
            robot=scenario.robot(),
            still_until=scenario.still_until,
            # The compiled integrator knows neither flow nor wakes.
            compiled=kernels.compiles(scenario.fish)
            and not any(scenario.flow)
            and scenario.wake_saving == 0,
            flow=scenario.flow,
            wake_saving=scenario.wake_saving,
            wake_length=scenario.wake_length,
            wake_width=scenario.wake_width,
        )

    def formation_at(self, time: float) -> str | None:
        """The formation fish are told to take at ``time`` by the scenario's switch (None:
        as configured)."""
        if self.switch_formation is not None and time >= self.switch_at:
            return self.switch_formation
        return None


def spawn_pose(params: WorldParams, fish_id: int) -> tuple[FloatArray, float]:
    """Initial position (3,) and yaw of one fish from its own stream: uniform in a ball
    around the tank centre (clipped into the tank) or in the whole tank; uniform yaw."""
    rng = stream(params.seed, Stream.SPAWN, fish_id)
    tank = params.tank
    if params.spawn_region == "tank":
        position = rng.uniform(0.0, 1.0, 3) * np.asarray(tank.size)
        return position, float(rng.uniform(-np.pi, np.pi))
    direction = rng.normal(size=3)
    direction /= max(float(np.linalg.norm(direction)), 1e-12)
    radius = params.spawn_radius * rng.uniform() ** (1 / 3)
    position = np.clip(tank.center + radius * direction, 0.0, np.asarray(tank.size))
    yaw = float(rng.uniform(-np.pi, np.pi))
    return position, yaw


def place(params: WorldParams, ids: IntArray) -> State:
    """Fish ``ids`` at rest at their spawn poses."""
    poses = [spawn_pose(params, int(i)) for i in ids]
    position = np.array([p for p, _ in poses]).reshape(-1, 3)
    yaw = np.array([y for _, y in poses])
    return rest_state(position, yaw)


@dataclass(frozen=True)
class StartLayout:
    """How fish ``0 … N − 1`` start.

    Attributes:
        spacing: the median distance from a fish to its nearest other, m (infinite for
            fewer than two fish).
        on_walls: how many start on the tank's walls, floor or surface: their place in the
            start ball lay outside the tank (uniform draws never land on them exactly).
    """

    spacing: float
    on_walls: int


def start_layout(params: WorldParams, fish: int) -> StartLayout:
    """How fish ``0 … fish − 1`` start at their spawn poses."""
    position = place(params, np.arange(fish, dtype=np.int64)).position
    on_walls = int(
        ((position <= 0.0) | (position >= np.asarray(params.tank.size))).any(axis=1).sum()
    )
    if fish < 2:
        return StartLayout(float("inf"), on_walls)
    distance, _ = cKDTree(position).query(position, k=2)
    return StartLayout(float(np.median(distance[:, 1])), on_walls)


def spawn_spacing(params: WorldParams, fish: int) -> float:
    """How far apart fish ``0 … fish − 1`` start: the median distance from a fish to its
    nearest other at the spawn poses, m (infinite for fewer than two fish)."""
    return start_layout(params, fish).spacing


def observe(
    state: State, *, params: WorldParams, rngs: list[np.random.Generator] | None = None
) -> Perceived:
    """What every fish sees of the others now (SPEC §1.2, or through its cameras), each with
    its own noise stream."""
    if params.cameras is not None:
        if rngs is None:
            raise ValueError("camera vision needs one random generator per fish")
        return perceive_through_cameras(
            state.position, state.yaw, cameras=params.cameras, rngs=rngs
        )
    vision = params.vision
    return perceive(
        state.position,
        state.yaw,
        vision=vision,
        rngs=rngs if vision.noise else None,
        kernels=kernels.CompiledVision() if params.compiled else None,
    )


def observe_landmarks(params: WorldParams, state: State) -> Perceived:
    """Which landmarks every fish sees now, in its body frame."""
    return perceive_landmarks(state.position, state.yaw, params.landmarks, vision=params.vision)


def advance(state: State, fins: FloatArray, *, duration: float, params: WorldParams) -> State:
    """Every fish swims ``duration`` s with its fins held (in the flow, sheltered by the
    wakes of the fish ahead as they are at the start of the interval)."""
    if params.compiled:
        return kernels.step(state, fins, duration=duration, robot=params.robot, tank=params.tank)
    drag_scale = None
    if params.wake_saving:
        shelter = wake_shelter(state, length=params.wake_length, width=params.wake_width)
        drag_scale = 1.0 - params.wake_saving * shelter
    return step(
        state, fins, duration=duration, robot=params.robot, tank=params.tank,
        flow=np.asarray(params.flow) if any(params.flow) else None, drag_scale=drag_scale,
    )  # fmt: skip
