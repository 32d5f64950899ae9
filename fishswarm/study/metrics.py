"""Swarm metrics on positions: the three mean distances of SPEC.md §3, neighbours seen, the
orbit metrics, and a formation's metrics against its target shape."""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree
from scipy.spatial.distance import pdist, squareform

from fishswarm.behaviors.formation import FormationParams
from fishswarm.bluebot.parameters import BODY_LENGTH
from fishswarm.formations.groups import Completion
from fishswarm.formations.metrics import (
    Alignment,
    align,
    collisions,
    deviation_energy,
    fish_fitness,
    local_shape_errors,
    shape_edges,
    shape_summary,
)
from fishswarm.sim import kernels
from fishswarm.sim.physics import WorldParams
from fishswarm.sim.scenario import Scenario
from fishswarm.study import distance_kernels

FloatArray = NDArray[np.float64]

METRIC_NAMES = ("centroid_distance", "pairwise_distance", "nearest_neighbor_distance")


def centroid_distance(position: FloatArray) -> float:
    """Distance of each fish to the centroid of the others, averaged over fish, m, from
    (N, 3) positions.

    What the research code printed as "mean inter-robot distance".
    """
    count = position.shape[0]
    if count < 2:
        return 0.0
    offset = position - (position.sum(axis=0) - position) / (count - 1)
    # The norm of each row written out, in numpy's order ((x² + y²) + z², the same bits as
    # np.linalg.norm(axis=1)) without its temporaries: 3× faster at 10 000 fish, where the
    # observer measures every snapshot while the workers decide.
    np.multiply(offset, offset, out=offset)
    squared = offset[:, 0] + offset[:, 1]
    squared += offset[:, 2]
    return float(np.sqrt(squared, out=squared).mean())


def linked_centroid_distance(
    position: FloatArray, *, link_range: float, manhattan: bool = False
) -> float:
    """The study code's "mean distance": each fish's distance to the centroid of the fish
    linked to it — every other fish within ``link_range``, before blind spot and occlusion
    filter any out — averaged over fish; a fish with no link counts 0 (SPEC §8), m.

    Args:
        position: (N, 3) positions, m.
        link_range: how far a link reaches, m (the visual range).
        manhattan: measure the link's length as |dx| + |dy| + |dz|, as the study's code did.
    """
    count = position.shape[0]
    if count < 2:
        return 0.0
    relative = position[None, :, :] - position[:, None, :]
    length = (
        np.abs(relative).sum(axis=2) if manhattan else np.sqrt((relative * relative).sum(axis=2))
    )
    linked = length <= link_range
    np.fill_diagonal(linked, False)
    links = linked.sum(axis=1)
    centre = (relative * linked[..., None]).sum(axis=1) / np.maximum(links, 1)[:, None]
    return float(np.linalg.norm(centre, axis=1).mean())


EXACT_PAIRS_MAX = 2_000_000
"""Swarms with at most this many pairs of fish (2 000 fish) get the exact mean pairwise
distance; larger ones an estimate from :data:`SAMPLED_PAIRS` pairs."""
SAMPLED_PAIRS = 250_000
"""How many pairs the mean pairwise distance of a swarm beyond :data:`EXACT_PAIRS_MAX` pairs
is estimated from: a standard error near 0.1 % of the mean (the distances' spread over their
mean, about 0.5 in a school spread over a tank, over √250 000), for 1–2 ms at 10 000 fish
where all 50 million pairs take 70–90 ms compiled — more than the world's own tick, and the
observer measures every snapshot."""


def pairwise_distance(position: FloatArray) -> float:
    """Mean distance over all pairs of fish, m.

    Exact up to :data:`EXACT_PAIRS_MAX` pairs; beyond, the mean over
    :data:`SAMPLED_PAIRS` pairs drawn uniformly, the same pairs for every snapshot of a swarm
    of that size (so the series is deterministic and moves only with the fish). From
    :data:`~fishswarm.sim.kernels.COMPILED_MIN_FISH` fish on, the distances are compiled
    (:mod:`fishswarm.study.distance_kernels`).
    """
    count = position.shape[0]
    if count < 2:
        return 0.0
    compiled = kernels.compiles(count)
    if (pairs := _pairs_measured(count)) is not None:
        first, second = pairs
        if compiled:
            return float(distance_kernels.pair_distances(position, first, second).mean())
        # Coordinate by coordinate: taking from one contiguous column is five times as
        # fast as gathering whole rows (2 against 10 ms at 10 000 fish), the sum the same.
        squared = np.zeros(first.shape[0])
        for column in np.ascontiguousarray(position.T):
            step = column.take(first) - column.take(second)
            squared += step * step
        return float(np.sqrt(squared).mean())
    if compiled:
        return distance_kernels.mean_pairwise_distance(position)
    return float(pdist(position).mean())


def _pairs_measured(count: int) -> tuple[NDArray[np.intp], NDArray[np.intp]] | None:
    """The pairs the mean pairwise distance of ``count`` fish is taken over: None for all
    of them, else :func:`_sampled_pairs`."""
    return _sampled_pairs(count) if count * (count - 1) // 2 > EXACT_PAIRS_MAX else None


@functools.lru_cache(maxsize=4)
def _sampled_pairs(count: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """:data:`SAMPLED_PAIRS` pairs of distinct fish among ``count``, uniform over all pairs,
    drawn from a generator seeded with ``count``."""
    rng = np.random.default_rng(count)
    first = rng.integers(0, count, SAMPLED_PAIRS).astype(np.intp)
    second = rng.integers(0, count - 1, SAMPLED_PAIRS).astype(np.intp)
    second += second >= first  # one of the other fish, each as likely
    return first, second


def nearest_neighbor_distance(position: FloatArray) -> float:
    """Distance of each fish to its nearest other fish, averaged over fish, m (compiled from
    :data:`~fishswarm.sim.kernels.COMPILED_MIN_FISH` fish on, the same distances)."""
    count = position.shape[0]
    if count < 2:
        return 0.0
    if kernels.compiles(count):
        return float(distance_kernels.nearest_distances(position).mean())
    distance, _ = cKDTree(position).query(position, k=2)
    return float(distance[:, 1].mean())


def effort_spread(effort: FloatArray) -> float:
    """How unevenly N fish have spent their effort: the most any fish spent over the mean
    (1: evenly; 1 also when nobody has spent anything)."""
    mean = float(effort.mean()) if effort.size else 0.0
    return float(effort.max()) / mean if mean > 0 else 1.0


def _pairwise_and_nearest(position: FloatArray) -> tuple[float, float]:
    """:func:`pairwise_distance` and :func:`nearest_neighbor_distance`, m, the same bits.

    A small swarm's both come from one set of pairwise distances (the nearest neighbour as
    the least of a fish's row: 25 fish, 23 µs against 49 with a k-d tree, which the observer
    spends on every snapshot); a compiled swarm's from one call to the kernels, which hold
    no GIL throughout (the observer's thread then needs it only before and after).
    """
    count = position.shape[0]
    if count < 2:
        return 0.0, 0.0
    if count < kernels.COMPILED_MIN_FISH:
        if not np.isfinite(position).all():  # as the k-d tree and the kernels refuse them
            raise ValueError("positions must be finite")
        distances = pdist(position)
        square = squareform(distances)
        np.fill_diagonal(square, np.inf)
        return float(distances.mean()), float(square.min(axis=1).mean())
    if not kernels.compiles(count):
        return pairwise_distance(position), nearest_neighbor_distance(position)
    pairwise, nearest = distance_kernels.school_distances(position, _pairs_measured(count))
    return pairwise, float(nearest.mean())


def prepare_metrics(fish: int) -> None:
    """Load what :func:`swarm_metrics` measures a swarm of ``fish`` with (from
    :data:`~fishswarm.sim.kernels.COMPILED_MIN_FISH` fish on: the compiled distances, from
    numba's cache or compiled, and the pairs sampled for the mean distance), so that the
    first snapshot does not wait for them: at 10 000 fish it took 0.27 s from the cache,
    while the world ran on five ticks, and the observer fell behind."""
    if not kernels.compiles(fish):
        return
    side = math.isqrt(fish - 1) + 1
    grid = np.arange(fish)
    position = np.stack([grid % side, grid // side, np.zeros(fish)], axis=1).astype(np.float64)
    # Read-only, as a snapshot's decoded positions are: numba compiles its loops anew for
    # arrays that cannot be written to.
    position.setflags(write=False)
    swarm_metrics(position, np.zeros(fish, dtype=np.int64), np.zeros(fish))


def swarm_metrics(
    position: FloatArray, neighbors_seen: NDArray[np.int64], effort: FloatArray | None = None
) -> dict[str, float]:
    """All metrics of one snapshot: the three distances (m), mean neighbours seen and, when
    the fish's efforts are known, the school's effort (gain-weighted fin beats) and its
    spread (the most a fish spent over the mean). With no fish (a world that lost them
    all), the distances and neighbours seen are not defined: NaN, not a school shrunk to a
    point."""
    if position.shape[0] == 0:
        return dict.fromkeys(
            ("centroid_distance", "pairwise_distance", "nearest_neighbor_distance",
             "neighbors_seen"),
            math.nan,
        )  # fmt: skip
    pairwise, nearest = _pairwise_and_nearest(position)
    metrics = {
        "centroid_distance": centroid_distance(position),
        "pairwise_distance": pairwise,
        "nearest_neighbor_distance": nearest,
        "neighbors_seen": float(neighbors_seen.mean()) if neighbors_seen.size else 0.0,
    }
    if effort is not None and effort.size:
        metrics["effort"] = float(effort.sum())
        metrics["effort_spread"] = effort_spread(effort)
    return metrics


ORBIT_METRIC_NAMES = ("radius", "revolutions", "speed", "collisions")


def orbit_metrics(
    position: FloatArray, *, centre: FloatArray | None, period: float, contact: float
) -> FloatArray:
    """Metrics of orbiting fish at every tick, from their positions.

    Args:
        position: (T, N, 3) positions, m.
        centre: (3,) the orbit centre, m; None for fish orbiting each other (waltz), whose
            centre is their barycentre at each tick.
        period: time between ticks, s.
        contact: two fish closer than this collide, m (one body length).

    Returns:
        (T, 4) columns: mean planar distance to the centre (m); revolutions so far (mean over
        fish of the unwrapped angle around the centre / 2π, positive in the direction the
        fish orbit: clockwise plotted with y up); mean planar speed over the last period
        (m/s, 0 at the first tick); colliding pairs.
    """
    steps = position.shape[0]
    middle = (
        position.mean(axis=1, keepdims=True)
        if centre is None
        else np.broadcast_to(np.asarray(centre, dtype=np.float64), (steps, 1, 3))
    )
    offset = position[..., :2] - middle[..., :2]
    radius = np.hypot(offset[..., 0], offset[..., 1]).mean(axis=1)
    angle = np.unwrap(np.arctan2(offset[..., 1], offset[..., 0]), axis=0)
    # The fish keep the centre on their left with z down: clockwise plotted with y up,
    # the direction of decreasing atan2(y, x); counted positive.
    revolutions = ((angle[0] - angle) / (2 * np.pi)).mean(axis=1)
    speed = np.zeros(steps)
    if steps > 1:
        moved = np.hypot(*np.moveaxis(np.diff(position[..., :2], axis=0), -1, 0))
        speed[1:] = moved.mean(axis=1) / period
    close = np.array([collisions(position[tick], distance=contact) for tick in range(steps)])
    return np.stack([radius, revolutions, speed, close.astype(np.float64)], axis=1)


ORBIT_BEHAVIORS = ("orbit", "milling", "waltz")
"""Behaviours measured by circling (radius, revolutions, speed, collisions)."""


@dataclass(frozen=True)
class OrbitTarget:
    """What an orbit run is measured against.

    Attributes:
        centre: (3,) the post the fish circle, m; None for partners circling each other
            (waltz), whose centre is their barycentre.
        radius: the orbit radius R (waltz: the partner distance), m.
    """

    centre: FloatArray | None
    radius: float

    @property
    def expected_radius(self) -> float:
        """The radius the fish should keep from the centre, m: R around a post; R/2 for
        partners R apart circling their barycentre."""
        return self.radius if self.centre is not None else self.radius / 2

    @property
    def label(self) -> str:
        """What the expected radius is, for a plot's key."""
        if self.centre is not None:
            return f"R = {self.radius:g} m"
        return f"R/2 (partners R = {self.radius:g} m apart)"


def orbit_target_of(scenario: Scenario) -> OrbitTarget | None:
    """The target of an orbit, milling or waltz run (None for other runs)."""
    if scenario.behavior not in ORBIT_BEHAVIORS:
        return None
    landmarks = scenario.landmarks()
    return OrbitTarget(landmarks[0] if landmarks.shape[0] else None, scenario.orbit_radius)


class OrbitTracker:
    """The orbit metrics snapshot by snapshot, as :func:`orbit_metrics` gives them for a
    whole run, for a live run whose fish may join or leave (each fish's revolutions count
    from its first snapshot; speed over fish present at both of the last two)."""

    def __init__(self, target: OrbitTarget, *, contact: float = BODY_LENGTH) -> None:
        self.target = target
        self.contact = contact
        self._ids = np.zeros(0, dtype=np.int64)
        self._start = np.zeros(0)
        self._angle = np.zeros(0)
        self._xy = np.zeros((0, 2))
        self._time = math.nan

    def metrics(
        self, ids: NDArray[np.int64], position: FloatArray, time: float
    ) -> dict[str, float]:
        """Radius (m), revolutions, speed (m/s) and colliding pairs of one snapshot.

        Args:
            ids: (N,) the fish.
            position: (N, 3) their positions, m.
            time: the snapshot's time, s.
        """
        if ids.size == 0:
            return dict.fromkeys(ORBIT_METRIC_NAMES, 0.0)
        xy = position[:, :2]
        centre = self.target.centre
        offset = xy - (xy.mean(axis=0) if centre is None else centre[:2])
        raw = np.arctan2(offset[:, 1], offset[:, 0])
        places = np.clip(np.searchsorted(self._ids, ids), 0, max(self._ids.size - 1, 0))
        known = (self._ids[places] == ids) if self._ids.size else np.zeros(ids.size, dtype=bool)
        before = np.where(known, self._angle[places] if self._ids.size else raw, raw)
        angle = before + (raw - before + np.pi) % (2 * np.pi) - np.pi
        start = np.where(known, self._start[places] if self._ids.size else raw, raw)
        speed = 0.0
        if known.any() and time > self._time:
            moved = np.hypot(*(xy[known] - self._xy[places[known]]).T)
            speed = float(moved.mean()) / (time - self._time)
        order = np.argsort(ids)
        self._ids, self._start, self._angle = ids[order], start[order], angle[order]
        self._xy, self._time = xy[order], time
        return {
            "radius": float(np.hypot(offset[:, 0], offset[:, 1]).mean()),
            # Clockwise plotted with y up (the fish keep the centre on their left, z down).
            "revolutions": float(((start - angle) / (2 * np.pi)).mean()),
            "speed": speed,
            "collisions": float(collisions(position, distance=self.contact)),
        }


FORMATION_METRIC_NAMES = (
    "shape_error",
    "joined_fraction",
    "lattice_energy",
    "collisions",
    "fitness",
)
"""A formation's metrics per snapshot: RMS error after the best rigid alignment and
assignment (m), the fraction of fish within the tolerance of their slot, the α-lattice
deviation energy, pairs closer than a body length, and the study's fitness of the school
(Σ F over its fish, m; a global map's only, NaN for a local shape)."""

CROWDING_SHARE = 0.125
"""The study's crowding radius as a share of the spacing: its code counts a neighbour as
crowding within 0.25 units of a fish on maps of spacing 2 units (``fitnes`` and
``valid_move`` in FishFormationSimulator/fish.py, fberlinger/FISH)."""


@dataclass(frozen=True)
class FormationTarget:
    """The shape a formation run is measured against.

    Attributes:
        slots: (S, 3) the target map in its own frame, m (made for the run's fish; fish
            that join later may outnumber it); None for a local shape.
        spacing: distance between neighbouring places, m.
        tolerance: a fish this close to its slot has joined, m.
        local_shape: the local shape measured around every fish (None for a global map).
        orientation: the formation's forward, rad in the tank frame (yaw).
    """

    slots: FloatArray | None
    spacing: float
    tolerance: float
    local_shape: str | None = None
    orientation: float = 0.0
    _last: dict[bytes, Alignment | Completion] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    def _fit(self, position: FloatArray) -> Alignment | Completion:
        """The school (N, 3) fitted to the target: a global map's alignment to its first N
        slots (all of them, when fish joined a school whose map was made for fewer), or how
        each fish completes its local shape. The last snapshot's is kept: an
        observer asks for the metrics and the roles of each snapshot, one fit serves both."""
        key = position.tobytes()
        fit = self._last.get(key)
        if fit is None:
            if self.local_shape is not None:
                fit = local_shape_errors(
                    position, self.local_shape, spacing=self.spacing, tolerance=self.tolerance
                )
            else:
                assert self.slots is not None
                fit = align(position, self.slots[: position.shape[0]], starts=6)
            self._last.clear()
            self._last[key] = fit
        return fit

    @property
    def crowding_radius(self) -> float:
        """Within this distance another fish crowds a fish in the study's fitness, m."""
        return CROWDING_SHARE * self.spacing

    def metrics(self, position: FloatArray) -> dict[str, float]:
        """The formation metrics of one snapshot. A global map: the school against its
        first N slots, and the study's fitness against those slots where the alignment
        lays them (more fish than slots: the fish that fit them best hold them, the others
        count as not joined). A local shape: every fish's group (it and its nearest neighbours)
        against the ideal shape, errors averaged over fish; joined when within tolerance."""
        if position.shape[0] == 0:
            return dict.fromkeys(FORMATION_METRIC_NAMES, math.nan)
        fit = self._fit(position)
        rms, joined = shape_summary(fit, self.tolerance)
        fitness = math.nan
        if isinstance(fit, Alignment):
            fitness = float(
                fish_fitness(
                    position,
                    fit.slots,
                    tolerance=self.tolerance,
                    crowding_radius=self.crowding_radius,
                ).sum()
            )
        return {
            "shape_error": rms,
            "joined_fraction": joined,
            "lattice_energy": deviation_energy(position, spacing=self.spacing),
            "collisions": float(collisions(position)),
            "fitness": fitness,
        }

    def roles(self, position: FloatArray) -> FormationRoles:
        """Who holds which place in one snapshot (N, 3), as an observer sees it from the
        positions alone (fish do not report their slots to observers): joined fish are within
        the tolerance of their slot of the aligned map (a local shape: their group within the
        tolerance); the leader, by the study's rule, is the fish furthest along the
        formation's orientation (a global map's; a local shape has none)."""
        count = position.shape[0]
        if self.local_shape is not None:
            local = self._fit(position)
            assert isinstance(local, Completion)
            return FormationRoles(
                local.joined(self.tolerance),
                np.zeros(count, dtype=np.bool_),
                None,
                shape_edges(local, self.tolerance, position=position, spacing=self.spacing),
            )
        if count == 0:
            return FormationRoles(
                np.zeros(count, dtype=np.bool_), np.zeros(count, dtype=np.bool_), None
            )
        fit = self._fit(position)
        assert isinstance(fit, Alignment)
        along = position[:, :2] @ np.array([math.cos(self.orientation), math.sin(self.orientation)])
        leader = np.zeros(count, dtype=np.bool_)
        leader[np.argmax(along)] = True
        return FormationRoles(fit.joined(self.tolerance), leader, fit.slots)


@dataclass(frozen=True)
class FormationRoles:
    """Who is where in a formation at one moment.

    Attributes:
        joined: (N,) fish within the tolerance of their place.
        leader: (N,) the fish furthest along a global map's orientation (none for a local
            shape).
        slots: (S, 3) the map's slots laid onto the school by the best rigid motion, m (None
            for a local shape): one for each fish, or fewer when more fish came than the map
            was made for.
        edges: (E, 2) bonds of completed local shapes: pairs of fish (indices) about a
            spacing apart in a shape they complete together (a star's centre and an arm,
            not two arms); none for a global map.
    """

    joined: NDArray[np.bool_]
    leader: NDArray[np.bool_]
    slots: FloatArray | None
    edges: NDArray[np.intp] = field(default_factory=lambda: np.zeros((0, 2), dtype=np.intp))


def formation_target_of(scenario: Scenario) -> FormationTarget | None:
    """The target of a formation run as configured, before any switch (None for other
    runs)."""
    targets = FormationTargets.of(scenario)
    return None if targets is None else targets.at(None)


def formation_target(params: FormationParams) -> FormationTarget:
    """The target formation fish with ``params`` make."""
    if params.is_local:
        return FormationTarget(None, params.spacing, params.tolerance, params.shape)
    return FormationTarget(
        params.slots(), params.spacing, params.tolerance, orientation=params.orientation
    )


class FormationTargets:
    """The targets of a formation run: its configured shape's and, made when first asked
    for, those of the shapes its fish are switched to (by the scenario, or by an operator's
    ``fishswarm formation``) — the same spacing, tolerance and heading, another shape."""

    def __init__(
        self,
        params: FormationParams,
        schedule: Callable[[float], str | None] = lambda time: None,
    ) -> None:
        self._params = params
        self._schedule = schedule
        self._targets: dict[str, FormationTarget] = {}

    @classmethod
    def of(cls, scenario: Scenario) -> FormationTargets | None:
        """The targets of a formation scenario (None for other runs), with its own switch
        (:meth:`WorldParams.formation_at <fishswarm.sim.physics.WorldParams.formation_at>`,
        what the world tells the fish)."""
        if scenario.behavior != "formation":
            return None
        params = scenario.fish_params().steering
        if not isinstance(params, FormationParams):
            return None
        return cls(params, WorldParams.of(scenario).formation_at)

    def told(self, formation: str | None, time: float) -> FormationTarget:
        """The target of the shape the fish were told to take at ``time``, s (see
        :meth:`shape_told`)."""
        return self.at(self.shape_told(formation, time))

    def shape_told(self, formation: str | None, time: float) -> str:
        """The shape the fish were told to take at ``time``, s: ``formation`` as a snapshot
        names it, or where it names none (recorded before snapshots did, or a batch
        engine's run) the scenario's own switch, or else its configured shape."""
        return formation or self._schedule(time) or self._params.shape

    def at(self, shape: str | None) -> FormationTarget:
        """The target of ``shape`` (None: the configured one)."""
        name = self._params.shape if shape is None else shape
        target = self._targets.get(name)
        if target is None:
            target = formation_target(dataclasses.replace(self._params, shape=name))
            self._targets[name] = target
        return target


def formation_summary(
    times: list[float], series: list[dict[str, float]], *, since: float = 0.0
) -> dict[str, Any]:
    """A formation run in a few numbers: the final metrics, the first time 90 % of the fish
    were in their slots (None if never), the most colliding pairs at once, and the study's
    fitness summed over the snapshots (SPEC §5: over fish and over time; None for a local
    shape). The time to 90 % and the sum count from ``since`` (s), when the fish were told
    the shape the final metrics measure: snapshots before it were judged against another."""
    final = {name: series[-1][name] for name in FORMATION_METRIC_NAMES}
    measured = [(t, m) for t, m in zip(times, series, strict=True) if t >= since]
    joined = [t for t, m in measured if m["joined_fraction"] >= 0.9]
    fitness = [m.get("fitness", math.nan) for _, m in measured]
    return {
        **final,
        "time_to_90_percent_joined": joined[0] if joined else None,
        "most_collisions": max(m["collisions"] for m in series),
        "fitness_total": None if math.isnan(sum(fitness)) else sum(fitness),
        "snapshots": len(measured),
    }
