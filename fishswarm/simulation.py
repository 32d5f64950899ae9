"""The simulated world as pure functions: place fish, see, move — and a batch engine.

This is the physics and vision the world actor wraps (like Gymnasium's pure ``FuncEnv``
with a thin stateful wrapper). :func:`run_batch` drives the same functions and the same
policy in one process, tick by tick, for fast sweeps and as a reference that the actor
system must reproduce bit for bit.

Random streams: one generator per (seed, role, fish id), derived with numpy's
``SeedSequence``, so that a fish's draws never depend on how many others there are or in
which process they run.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from fishswarm.behaviors.policy import Memory, Policy, act
from fishswarm.bluebot.dynamics import State, rest_state, step
from fishswarm.bluebot.parameters import BlueBot
from fishswarm.bluebot.vision import Perceived, perceive, perceive_landmarks
from fishswarm.learning.replica_file import ReplicaFileError, load_replica
from fishswarm.scenario import ConfigError, Scenario

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


class Stream(enum.IntEnum):
    """Roles that own a random stream."""

    SPAWN = 1
    VISION = 2
    CHANNEL = 3
    JITTER = 4


def stream(seed: int, role: Stream, member: int) -> np.random.Generator:
    """The random generator of ``member`` in ``role`` for master ``seed``."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(int(role), member)))


def spawn_pose(scenario: Scenario, fish_id: int) -> tuple[FloatArray, float]:
    """Initial position (3,) and yaw of one fish: uniform in a ball around the tank centre
    (clipped into the tank), uniform yaw."""
    rng = stream(scenario.seed, Stream.SPAWN, fish_id)
    tank = scenario.the_tank()
    if scenario.spawn_region == "tank":
        position = rng.uniform(0.0, 1.0, 3) * np.asarray(tank.size)
        return position, float(rng.uniform(-np.pi, np.pi))
    direction = rng.normal(size=3)
    direction /= max(float(np.linalg.norm(direction)), 1e-12)
    radius = scenario.resolved_spawn_radius() * rng.uniform() ** (1 / 3)
    position = np.clip(tank.center + radius * direction, 0.0, np.asarray(tank.size))
    yaw = float(rng.uniform(-np.pi, np.pi))
    return position, yaw


def place(scenario: Scenario, ids: IntArray) -> State:
    """Fish ``ids`` at rest at their spawn poses."""
    poses = [spawn_pose(scenario, int(i)) for i in ids]
    position = np.array([p for p, _ in poses]).reshape(-1, 3)
    yaw = np.array([y for _, y in poses])
    return rest_state(position, yaw)


def policy_of(scenario: Scenario) -> Policy:
    """The policy every fish of the scenario follows (reads the replica model if any).

    Raises:
        ConfigError: the model file is not a learned replica.
    """
    weights = None
    if scenario.behavior == "replica":
        assert scenario.model is not None
        try:
            loaded, _ = load_replica(Path(scenario.model))
        except ReplicaFileError as error:
            raise ConfigError(str(error)) from None
        weights = tuple(float(w) for w in loaded)
    return Policy(
        behavior=scenario.behavior,
        target_distance=scenario.resolved_target_distance(),
        controller=scenario.controller,
        control_period=scenario.control_period,
        caudal_cap=scenario.caudal_cap,
        replica_weights=weights,
        orbit_radius=scenario.orbit_radius,
    )


def observe(
    scenario: Scenario, state: State, rngs: list[np.random.Generator] | None = None
) -> Perceived:
    """What every fish sees now (vision of SPEC §1.2)."""
    vision = scenario.vision()
    return perceive(state.position, state.yaw, vision=vision, rngs=rngs if vision.noise else None)


def observe_landmarks(scenario: Scenario, state: State) -> Perceived:
    """Which of the scenario's landmarks every fish sees now, in its body frame."""
    return perceive_landmarks(
        state.position, state.yaw, scenario.landmarks(), vision=scenario.vision()
    )


def advance(
    scenario: Scenario,
    state: State,
    fins: FloatArray,
    robot: BlueBot = BlueBot(),
    *,
    duration: float | None = None,
) -> State:
    """Move every fish through one control period (or ``duration`` s) with its fins held."""
    period = scenario.control_period if duration is None else duration
    return step(state, fins, duration=period, robot=robot, tank=scenario.the_tank())


@dataclass(frozen=True)
class Trajectory:
    """Recorded states of a run, SI units.

    Attributes:
        t: (T,) times, s.
        ids: (N,) fish ids.
        position: (T, N, 3) tank frame, m.
        velocity: (T, N, 3) tank frame, m/s.
        yaw: (T, N) rad.
        neighbors_seen: (T, N) neighbours seen at each tick.
    """

    t: FloatArray
    ids: IntArray
    position: FloatArray
    velocity: FloatArray
    yaw: FloatArray
    neighbors_seen: IntArray


class TrajectoryRecorder:
    """Collects the fish at each snapshot and makes a :class:`Trajectory` of them."""

    def __init__(self) -> None:
        self._rows: list[tuple[float, FloatArray, FloatArray, FloatArray, IntArray]] = []

    def add(self, time: float, state: State, perceived: Perceived) -> None:
        """Record the fish at ``time``, with the neighbours each sees."""
        self._rows.append(
            (time, state.position, state.tank_velocity(), state.yaw, perceived.counts)
        )

    def trajectory(self, ids: IntArray) -> Trajectory:
        """Everything recorded, as arrays."""
        times, positions, velocities, yaws, seen = zip(*self._rows, strict=True)
        return Trajectory(
            np.array(times),
            ids,
            np.array(positions),
            np.array(velocities),
            np.array(yaws),
            np.array(seen),
        )


def run_batch(scenario: Scenario) -> Trajectory:
    """Run a scenario in this process, all fish as one batch, and record every tick.

    The sequence per tick matches the actor system exactly: observe → every fish acts on its
    perception → advance. Tick 0 is the initial state. In jitter mode the events of
    :func:`fishswarm.jitter.run_jittered`.
    """
    if scenario.time_mode == "jitter":
        from fishswarm.jitter import run_jittered  # jitter builds on this module

        return run_jittered(scenario)
    ids = np.arange(scenario.fish, dtype=np.int64)
    state = place(scenario, ids)
    policy = policy_of(scenario)
    memory = Memory.fresh(scenario.fish)
    vision_rngs = [stream(scenario.seed, Stream.VISION, int(i)) for i in ids]
    recorder = TrajectoryRecorder()
    for tick in range(scenario.ticks + 1):
        perceived = observe(scenario, state, vision_rngs)
        recorder.add(tick * scenario.control_period, state, perceived)
        if tick == scenario.ticks:
            break
        landmarks = observe_landmarks(scenario, state)
        fins, memory = act_each(policy, perceived, landmarks, state.position[:, 2], memory)
        state = advance(scenario, state, fins)
    return recorder.trajectory(ids)


def act_each(
    policy: Policy, perceived: Perceived, landmarks: Perceived, depth: FloatArray, memory: Memory
) -> tuple[FloatArray, Memory]:
    """All fish act at once on their perceptions.

    The actor system runs the same policy with a batch of one per fish; batch and loop agree
    exactly (tested), so this is the fast path for the same result.
    """
    return act(
        policy,
        perceived.neighbors,
        perceived.mask,
        depth,
        memory,
        landmarks.neighbors,
        landmarks.mask,
    )
