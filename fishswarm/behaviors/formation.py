"""The formation behaviour: fish take their places in a shape by local decisions, and tell
each other with formation flags (SPEC §5).

Each decision, for B fish at once:

1. the candidate places — a global map's slots, anchored at the leader a fish sees and
   turned to the formation's orientation; or the spots that complete a local shape with its
   nearest neighbours (:mod:`fishswarm.formations`);
2. what the inbox says: a neighbour that flagged itself joined holds its slot (global) or
   the spot where it stands (local) — the fish does not contend for it;
3. the study's rule picks a place (or none: stay), the fish steers to it — aiming short of
   it by the drift it predicts from its own velocity relative to the place (the lead), so
   that it brakes before it arrives;
4. a fish within the tolerance of its place has joined; with flags on it broadcasts a
   :class:`~fishswarm.protocols.messages.FormationFlag` (shape, slot, joined, hops from the
   leader, the orientation it follows, a sequence number) — on a robot its driver flashes
   the LEDs while the flag says joined (:mod:`fishswarm.bluebot.flashes`); the LEDs stay
   lit all the while, since neighbours see a robot by them.

The orientation is a direction of the tank; a fish finds it in its own frame from its
compass heading (the simulated world gives every fish one). A fish without a heading takes
its own forward as the orientation.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fishswarm.behaviors.core import (
    Behavior,
    FishMemory,
    FishParams,
    Inbox,
    Outbox,
    Perception,
    Steering,
)
from fishswarm.bluebot.control import PidGains
from fishswarm.bluebot.dynamics import rotate_to_tank
from fishswarm.bluebot.parameters import BODY_LENGTH
from fishswarm.formations.lattice import close_packing, star_map
from fishswarm.formations.local import LOCAL_SHAPES, local_spots
from fishswarm.formations.maps import target_map
from fishswarm.formations.rules import (
    STAY,
    choose_spot,
    leader_and_rank,
    nearest_only,
    place_map,
)
from fishswarm.protocols.messages import (
    BROADCAST_KINDS,
    BROADCAST_WIDTH,
    FORMATION_SHAPES,
    FormationFlag,
)

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

DEFAULT_SHAPE = "pyramid"
"""The formation fish take when none is named."""
DEFAULT_SPACING = 0.3
"""Default distance between neighbouring places, m (about 2.3 body lengths)."""
DEFAULT_LEAD = 2.5
"""Default lead, s: how far ahead a fish predicts its drift when it aims at its place."""

FORMATION_KIND = BROADCAST_KINDS.index("formation")
NO_HOPS = 10_000
"""The hop count of a fish that has heard of no leader."""
SLOT_RULES = ("share", "study")
LOCAL_RULES = ("lattice", "neighbors")
"""How fish make a local shape: places on the shape's lattice anchored at the leader (for
shapes that have one, :data:`LATTICES`), or spots next to their nearest neighbours."""
LATTICES: dict[str, Callable[..., FloatArray]] = {
    "trigonal-planar": star_map,
    "tetrahedron": close_packing,
}
"""The local shapes with a map of places where every fish completes one."""
DEFAULT_EFFORT_MARGIN = 40.0
"""Default margin of effort sharing, gain-weighted fin beats (set from measurements, see
docs/formations.md)."""
SWAP_TIMEOUT = 20.0
"""A swap of places not completed within this time is given up, s."""
NEIGHBOUR_SPACINGS = 1.5
"""A fish asks only fish within this many spacings of it to swap places: its neighbours."""
SWAP_REST = 30.0
"""A fish that began a swap asks for no other within this time, s: it rests in its new
place (accumulated effort changes slowly, so without a rest it would swap on and on)."""
EFFORT_COLUMN, SWAP_COLUMN = 6, 7
"""Where a formation flag's effort and swap request sit among a broadcast's numbers."""


@dataclass(frozen=True)
class FormationParams:
    """Parameters of the formation behaviour.

    Attributes:
        shape: a global map (:data:`fishswarm.formations.maps.MAPS`) or a local shape
            (:data:`fishswarm.formations.local.LOCAL_SHAPES`).
        count: fish in the school (the size of a global map).
        spacing: distance between neighbouring places, m.
        tolerance: a fish this close to its place has joined, m.
        orientation: the formation's forward, rad in the tank frame (yaw).
        flags: broadcast formation flags and heed those heard.
        rule: how a fish picks its slot in a global map: ``study`` (the slot of its rank,
            or the next one that is free and that its nearest neighbour is not nearer to)
            or ``share`` (the free slots shared out among itself and the neighbours that
            hold none, nearest pairs first — fish that see the same fish agree).
        lead: a fish aims at its place minus ``lead`` times its velocity relative to the
            place, s; 0 aims at the place itself. A BlueBot cannot swim backwards and
            its drag is quadratic, so it glides far at low speed: without a lead it circles
            its place instead of stopping on it.
        station: a global map's slot 0 is this far behind the first landmark (against the
            orientation), m, for a fish that sees the landmark — the leader holds station
            there, in a flow; None: the map is anchored at the leader.
        rotate_effort: share the effort (global maps, with flags): a fish whose effort
            exceeds that of the most rested fish it hears by ``effort_margin`` asks it to
            swap places; the asked fish agrees by flag and both move (:func:`share_effort`).
        effort_margin: gain-weighted fin beats.
        local_rule: how fish make a local shape: ``lattice`` — a map of places where every
            fish completes the shape, anchored at the leader like a global map (stars and
            tetrahedra, :data:`LATTICES`; triangles are made with neighbours whatever this
            says) — or ``neighbors``: spots that complete it with the fish's nearest
            neighbours.
    """

    shape: str
    count: int
    spacing: float = DEFAULT_SPACING
    tolerance: float = 0.25 * DEFAULT_SPACING
    orientation: float = 0.0
    flags: bool = True
    rule: str = "share"
    lead: float = DEFAULT_LEAD
    station: float | None = None
    rotate_effort: bool = False
    effort_margin: float = DEFAULT_EFFORT_MARGIN
    local_rule: str = "lattice"

    def __post_init__(self) -> None:
        if self.rule not in SLOT_RULES:
            raise ValueError(f"slot rule must be one of {', '.join(SLOT_RULES)}, got {self.rule!r}")
        if self.local_rule not in LOCAL_RULES:
            raise ValueError(
                f"local rule must be one of {', '.join(LOCAL_RULES)}, got {self.local_rule!r}"
            )
        if self.shape not in FORMATION_SHAPES:
            raise ValueError(
                f"formation must be one of {', '.join(FORMATION_SHAPES)}, got {self.shape!r}"
            )
        if not self.spacing > 0 or not self.tolerance > 0:
            raise ValueError("formation spacing and tolerance must be positive lengths")
        if not 0 <= self.lead < math.inf:
            raise ValueError(f"formation lead must be a time of 0 s or more, got {self.lead!r}")

    @property
    def is_local(self) -> bool:
        """Whether the shape is local (judged with the nearest neighbours)."""
        return self.shape in LOCAL_SHAPES

    @property
    def uses_map(self) -> bool:
        """Whether fish take places on a map anchored at the leader: a global map's, or a
        local shape's lattice."""
        return not self.is_local or (self.local_rule == "lattice" and self.shape in LATTICES)

    def slots(self) -> FloatArray:
        """(count, 3) the map's places in the formation frame, m (global maps and lattices).

        Raises:
            ValueError: a shape made with neighbours, which has no map.
        """
        if not self.uses_map:
            raise ValueError(f"{self.shape} is made with neighbours: it has no map")
        make = LATTICES.get(self.shape)
        if make is not None:
            return make(self.count, spacing=self.spacing)
        return target_map(self.shape, self.count, spacing=self.spacing)


@dataclass(frozen=True)
class FormationMemory:
    """What formation fish remember: (B,) their last place (−1: none), whether they had
    joined, how many flags each has sent, and where their place was at their last
    decision — (B, 3) in the tank's orientation, m (NaN: unknown) — and when (B,) s; and
    a swap of places under way: (B,) the slot a fish moves to (−1: none), the slot it gave
    up, and since when, s."""

    place: IntArray
    joined: BoolArray
    sequence: IntArray
    place_vector: FloatArray
    place_time: FloatArray
    swap_to: IntArray
    swap_from: IntArray
    swap_since: FloatArray


def fresh_formation_memory(count: int) -> FormationMemory:
    """Fish that have no place yet."""
    return FormationMemory(
        np.full(count, STAY, dtype=np.int64),
        np.zeros(count, dtype=np.bool_),
        np.zeros(count, dtype=np.int64),
        np.full((count, 3), np.nan),
        np.full(count, np.nan),
        np.full(count, STAY, dtype=np.int64),
        np.full(count, STAY, dtype=np.int64),
        np.full(count, np.nan),
    )


def formation_params(settings: Mapping[str, Any]) -> FormationParams:
    """The behaviour's parameters from a scenario's settings (``formation``, ``spacing``,
    ``tolerance``, ``formation_heading_deg``, ``flags``, ``fish``, ``slot_rule``,
    ``formation_lead``, ``station_distance``, ``rotate_effort``, ``effort_margin``,
    ``local_rule``)."""
    spacing = settings.get("spacing")
    spacing = DEFAULT_SPACING if spacing is None else float(spacing)
    tolerance = settings.get("tolerance")
    station = settings.get("station_distance")
    shape = str(settings.get("formation") or DEFAULT_SHAPE)
    rotate_effort = bool(settings.get("rotate_effort", False))
    if rotate_effort and shape in LOCAL_SHAPES:
        # Refused here, where a user asks for it; a live switch to a local shape only pauses
        # the sharing (it swaps the places of a global map).
        raise ValueError(
            f"effort sharing swaps the places of a global map; {shape} is a local shape: "
            "choose a global map or drop --rotate-effort (rotate_effort)"
        )
    return FormationParams(
        shape=shape,
        count=int(settings.get("fish", 15)),
        spacing=spacing,
        tolerance=0.25 * spacing if tolerance is None else float(tolerance),
        orientation=math.radians(float(settings.get("formation_heading_deg", 0.0))),
        flags=bool(settings.get("flags", True)),
        rule=str(settings.get("slot_rule") or "share"),
        lead=float(settings.get("formation_lead", DEFAULT_LEAD)),
        station=None if station is None else float(station),
        rotate_effort=rotate_effort,
        effort_margin=float(settings.get("effort_margin", DEFAULT_EFFORT_MARGIN)),
        local_rule=str(settings.get("local_rule") or "lattice"),
    )


def _orientation(perception: Perception, params: FormationParams) -> FloatArray:
    """(B, 3) the formation's forward in each fish's body frame."""
    count = perception.count
    heading = np.full(count, np.nan) if perception.heading is None else perception.heading
    angle = np.where(np.isnan(heading), 0.0, params.orientation - heading)
    return np.stack([np.cos(angle), np.sin(angle), np.zeros(count)], axis=1)


@dataclass(frozen=True)
class HeardFlags:
    """What the formation flags in B fish's inboxes say, row by row (B, M).

    Attributes:
        flag: the row is a flag of this formation.
        joined: ... of a fish in its place.
        slot: the place it holds or seeks.
        leader: ... of a fish that leads (hops 0).
        fewest_hops: (B,) the fewest hops to the leader heard.
    """

    flag: BoolArray
    joined: BoolArray
    slot: IntArray
    leader: BoolArray
    fewest_hops: IntArray


def flag_by_light(own: FormationFlag) -> FormationFlag:
    """What a robot learns from a neighbour whose LEDs flash, as a formation flag: the
    neighbour holds its place (:mod:`fishswarm.bluebot.flashes`).

    The light says nothing else. The flag takes the shape and orientation of the robot's
    own last flag (the robots of a tank take one formation), no slot (so no swap of places
    is asked of it), no hops from a leader, and no effort.
    """
    return FormationFlag(own.shape, -1, True, NO_HOPS, own.heading_mdeg, 0)


def flag_seen_in_light(params: FishParams, told: str | None) -> FormationFlag | None:
    """What a simulated fish of ``params`` takes a robot's flashing LEDs for, in the shape
    it is told (``told``; None: its own): that the robot holds its place in that shape, as
    :func:`flag_by_light` says it (shape and orientation the fish's own). None when the fish
    do not heed flags (another behaviour, or flags off)."""
    if told is not None:
        params = with_formation(params, told)
    steering = params.steering
    if params.behavior.name != FORMATION.name or not isinstance(steering, FormationParams):
        return None
    if not steering.flags:
        return None
    # All that light carries of the fish's own flag: its shape and orientation.
    shape = FORMATION_SHAPES.index(steering.shape)
    own = FormationFlag(shape, -1, False, NO_HOPS, _heading_mdeg(steering.orientation), 0)
    return flag_by_light(own)


def _heading_mdeg(orientation: float) -> int:
    """A formation's orientation as a flag carries it: millidegrees in (−180°, 180°]."""
    return round(math.degrees(math.remainder(orientation, 2 * math.pi)) * 1000)


def _heard_flags(inbox: Inbox, params: FormationParams) -> HeardFlags:
    """What the flags of this formation in the inbox say (nothing with flags off)."""
    shape = FORMATION_SHAPES.index(params.shape)
    values = inbox.values
    same = inbox.mask & (inbox.kind == FORMATION_KIND) & (values[..., 0] == shape)
    same &= np.bool_(params.flags)
    joined = same & (values[..., 2] == 1)
    hops = np.where(same, values[..., 3], NO_HOPS)
    fewest = hops.min(axis=1) if hops.shape[1] else np.full(inbox.mask.shape[0], NO_HOPS)
    return HeardFlags(same, joined, values[..., 1], same & (hops == 0), fewest.astype(np.int64))


def _with_senders(
    neighbors: FloatArray, mask: BoolArray, inbox: Inbox, heard: HeardFlags, params: FormationParams
) -> tuple[FloatArray, BoolArray, BoolArray]:
    """The fish a fish knows of: those it sees and those whose flags it hears (where they
    appear: a flag shows its sender's place even when a nearer fish hides it), each once.

    Returns:
        (B, K + M, 3) positions, (B, K + M) which are real, and (B, K + M) which are heard
        to hold their slot (joined flags that name it: such a slot is claimed, and its
        holder does not take part in sharing the others out). A flag by light names no slot
        (:func:`flag_by_light`): its sender stands where it is seen, as any fish seen does.
    """
    senders = heard.flag
    both = bool(neighbors.shape[1] and senders.shape[1])
    if both:
        # (B, K, M) how far each seen fish is from where each flag's sender appears.
        gaps = np.linalg.norm(neighbors[:, :, None, :] - inbox.sender[:, None, :, :], axis=3)
        near = gaps < params.tolerance / 2
        senders = senders & ~(near & mask[:, :, None]).any(axis=1)
    known = np.concatenate([neighbors, inbox.sender], axis=1)
    real = np.concatenate([mask, senders], axis=1)
    named = heard.joined & (heard.slot >= 0)
    holding = np.concatenate([np.zeros_like(mask), named & senders], axis=1)
    if both:
        # A seen fish whose flag says it holds its slot holds it too.
        holding[:, : mask.shape[1]] = (near & named[:, None, :]).any(axis=2)
    return known, real, holding


def _agreed_leader(
    leader: FloatArray,
    rank: IntArray,
    inbox: Inbox,
    leaders: BoolArray,
    axis: FloatArray,
    *,
    led: BoolArray,
    margin: float,
) -> tuple[FloatArray, IntArray]:
    """The leader the flags agree on: a fish that hears a leader's flag anchors its map where
    that leader appears — the one furthest along the orientation if it hears several — if
    the leader is ahead of the fish; a fish that did not lead at its last decision (``led``
    false) follows a flagged leader up to ``margin`` m behind it too. A fish ahead of every
    flagged leader leads itself.

    The margin keeps the lead where it is while fish pass the leader on their way to their
    places: without it a fish that swims past the leader takes the lead, every fish's map
    jumps with it, and the old leader, no longer leading, swims off — and a BlueBot glides
    for tens of seconds after a stroke."""
    along = np.einsum("bmd,bd->bm", inbox.sender, axis)
    along = np.where(leaders, along, -np.inf)
    if along.shape[1] == 0:
        return leader, rank
    best = np.argmax(along, axis=1)
    rows = np.arange(leader.shape[0])
    follows = along[rows, best] > np.where(led, 0.0, -margin)
    agreed = np.where(follows[:, None], inbox.sender[rows, best], leader)
    return agreed, np.where(follows & (rank == 0), 1, rank)


def _settled(places: FloatArray, neighbors: FloatArray, params: FormationParams) -> BoolArray:
    """(B, K) the neighbours within the tolerance of one of the places: they hold it."""
    if neighbors.shape[1] == 0 or places.shape[1] == 0:
        return np.zeros(neighbors.shape[:2], dtype=np.bool_)
    gaps = np.linalg.norm(neighbors[:, :, None, :] - places[:, None, :, :], axis=3)
    settled: BoolArray = (gaps <= params.tolerance).any(axis=2)
    return settled


@dataclass(frozen=True)
class _Swaps:
    """Swaps of places for effort sharing, (B,) each: the slot a fish moves to (−1: none),
    the slot it gave up, since when (s), and the swap field of its flag (−1: none)."""

    swap_to: IntArray
    swap_from: IntArray
    swap_since: FloatArray
    asking: IntArray

    @classmethod
    def none(cls, memory: FormationMemory) -> _Swaps:
        """No swap under way or asked for (the memory's record of swaps as it was)."""
        return cls(
            memory.swap_to, memory.swap_from, memory.swap_since, np.full_like(memory.place, STAY)
        )


def share_effort(
    memory: FormationMemory,
    effort: FloatArray,
    inbox: Inbox,
    heard: HeardFlags,
    *,
    slots: int,
    now: FloatArray,
    params: FormationParams,
) -> _Swaps:
    """Swaps of places that share a formation's effort, by a handshake of flags (the swap
    field names a slot). A costly place (the front, where no wake helps; a place that needs
    much steering) shows in the effort of the fish that holds it:

    1. *ask*: a fish holding a slot whose effort exceeds that of the most rested neighbour
       it hears (within :data:`NEIGHBOUR_SPACINGS`, holding a slot, asking nothing) by
       more than the margin flags that fish's slot, joined, and stays;
    2. *agree*: the fish holding that slot, hearing it, moves to the asker's slot, flagging
       that it seeks it (not joined) and gives up its own;
    3. *go*: the asker, hearing a fish seek its slot and give one up, moves to that one.

    A swap under way lasts until the fish holds its new place (at its last decision) or
    :data:`SWAP_TIMEOUT` passes. Fish busy with a swap neither ask nor agree; a fish asks
    for no swap within :data:`SWAP_REST` of its last one.

    Args:
        memory: the fish's formation memory.
        effort: (B,) each fish's own effort so far, gain-weighted fin beats.
        inbox: their inboxes.
        heard: what the formation flags in them say.
        slots: the number of slots in the map.
        now: (B,) the time of the decision, s.
        params: the behaviour's parameters.
    """
    count = memory.place.shape[0]
    rows = np.arange(count)
    told_effort = inbox.values[..., EFFORT_COLUMN]
    told_swap = inbox.values[..., SWAP_COLUMN] - 1
    slot = heard.slot
    in_map = heard.flag & (slot >= 0) & (slot < slots)
    arrived = memory.joined & (memory.place == memory.swap_to)
    busy = (memory.swap_to >= 0) & ~arrived & (now - memory.swap_since < SWAP_TIMEOUT)
    place = memory.place
    if not slot.shape[1]:  # nothing heard: nobody to ask or answer; swaps under way go on
        swap_to = np.where(busy, memory.swap_to, STAY)
        swap_from = np.where(busy, memory.swap_from, STAY)
        return _Swaps(swap_to, swap_from, memory.swap_since, np.where(busy, swap_from, STAY))
    # Without a station the map is anchored at its leader, slot 0: a leader that left it for
    # another slot would carry the map along with it (the school chased it into a corner).
    # So slot 0 is swapped only when it is a place in the water, behind the station's post.
    swappable = in_map & ((slot > 0) | (params.station is not None))
    holds = memory.joined & (place >= 0) & ~busy
    holds &= (place > 0) | (params.station is not None)
    asked = swappable & heard.joined & (told_swap == place[:, None]) & holds[:, None]
    # The slot a seeker offers must be on this fish's map too: a flag from a fish with a
    # larger map (or a forged one) may name one past its end.
    offered = (told_swap >= 0) & (told_swap < slots)
    answered = in_map & ~heard.joined & (slot == place[:, None]) & offered & holds[:, None]
    agree, go = asked.any(axis=1), answered.any(axis=1) & ~asked.any(axis=1)
    new_slot = np.where(
        agree, slot[rows, np.argmax(asked, axis=1)], told_swap[rows, np.argmax(answered, axis=1)]
    )
    starting = agree | go
    swap_to = np.where(busy, memory.swap_to, np.where(starting, new_slot, STAY))
    swap_from = np.where(busy, memory.swap_from, np.where(starting, place, STAY))
    since = np.where(starting, now, memory.swap_since)
    resting = now - since < SWAP_REST
    # Only a neighbour, the holder of a slot next to the fish's own, is asked: a short swap.
    near = np.linalg.norm(inbox.sender, axis=2) <= NEIGHBOUR_SPACINGS * params.spacing
    rested = swappable & heard.joined & (told_swap < 0) & near
    lowest = np.where(rested, told_effort, np.iinfo(np.int64).max)
    pick = np.argmin(lowest, axis=1)
    least = lowest[rows, pick]
    tired = holds & ~starting & ~resting & rested.any(axis=1)
    tired &= effort - least > params.effort_margin
    asking = np.where(swap_to >= 0, swap_from, np.where(tired, slot[rows, pick], STAY))
    return _Swaps(
        swap_to.astype(np.int64), swap_from.astype(np.int64), since, asking.astype(np.int64)
    )


def lead_aim(
    target: FloatArray,
    *,
    heading: FloatArray,
    previous: FloatArray,
    elapsed: FloatArray,
    same_place: BoolArray,
    lead: float,
) -> tuple[FloatArray, FloatArray]:
    """Where B fish aim to stop on their places: each place minus ``lead`` times the fish's
    velocity relative to it, estimated from how the place moved since the last decision.

    The estimate needs the fish's compass heading (to compare the two body frames) and the
    same place at both decisions; other fish aim at the place itself.

    Args:
        target: (B, 3) each fish's place in its body frame, m.
        heading: (B,) compass headings, rad (NaN: none).
        previous: (B, 3) the place at the last decision in the tank's orientation, m (NaN:
            none).
        elapsed: (B,) time since the last decision, s.
        same_place: (B,) the fish seeks the place it sought at the last decision.
        lead: s.

    Returns:
        (B, 3) the aim in the body frame, m, and (B, 3) the place in the tank's
        orientation (the next decision's ``previous``; NaN without a heading), m.
    """
    has_heading = ~np.isnan(heading)
    yaw = np.where(has_heading, heading, 0.0)
    place = np.where(has_heading[:, None], rotate_to_tank(target, yaw), np.nan)
    known = same_place & has_heading & (elapsed > 0) & ~np.isnan(previous).any(axis=1)
    step = np.where(known, elapsed, 1.0)[:, None]
    # The place stands still in the tank, so it moves against the fish: v = −Δplace / Δt.
    velocity = np.where(known[:, None], (previous - place) / step, 0.0)
    aim = rotate_to_tank(place - lead * velocity, -yaw)  # back into the body frame
    return np.where(known[:, None], aim, target), place


def steer_formation(
    memory: FormationMemory, perception: Perception, inbox: Inbox, *, params: FormationParams
) -> tuple[FormationMemory, Steering]:
    """Take a place in the formation, flagging it once there."""
    count = perception.count
    neighbors, mask = perception.neighbors, perception.neighbor_mask
    orientation = _orientation(perception, params)
    heard = _heard_flags(inbox, params)
    rank = np.zeros(count, dtype=np.int64)
    if not params.uses_map:
        places, valid, preference = local_spots(
            params.shape, neighbors, mask, spacing=params.spacing
        )
        rivals = nearest_only(neighbors, mask, skip=LOCAL_SHAPES[params.shape])
        # A spot is claimed when a neighbour that flagged itself joined stands on it.
        gaps = np.linalg.norm(places[:, :, None, :] - inbox.sender[:, None, :, :], axis=3)
        claimed = (heard.joined[:, None, :] & (gaps <= params.tolerance)).any(axis=2)
        chosen = choose_spot(
            places, valid, neighbors, mask, tolerance=params.tolerance, rivals=rivals,
            claimed=claimed,
            preference=preference,
        )  # fmt: skip
    else:
        slots = params.slots()
        known, real, holding = _with_senders(neighbors, mask, inbox, heard, params)
        leader, rank = leader_and_rank(known, real, orientation)
        # With a station, slot 0 is a place behind the post, not the leader's: holding it
        # says nothing of leading, and the leader's rules below stay off.
        led = (memory.place == 0) & np.bool_(params.station is None)
        if params.flags:
            # A leader keeps the lead against fish that pass it by less than a spacing (they
            # follow its flag): see _agreed_leader.
            keeps = led & (np.einsum("bd,bd->b", leader, orientation) <= params.spacing)
            leader = np.where(keeps[:, None], 0.0, leader)
            rank = np.where(keeps, 0, rank)
        leader, rank = _agreed_leader(
            leader, rank, inbox, heard.leader, orientation,
            led=led, margin=params.spacing if params.station is None else 0.0,
        )  # fmt: skip
        leads = rank == 0
        if params.station is not None and perception.landmarks.shape[1]:
            # A fish that sees the landmark knows where the station is: slot 0 goes there.
            station = perception.landmarks[:, 0] - params.station * orientation
            leader = np.where(perception.landmark_mask[:, :1], station, leader)
            leads &= ~perception.landmark_mask[:, 0]
        places = place_map(leader, orientation, slots)
        valid = np.ones(places.shape[:2], dtype=np.bool_)
        claimed = np.zeros(places.shape[:2], dtype=np.bool_)
        in_map = heard.joined & (heard.slot >= 0) & (heard.slot < params.count)
        rows, columns = np.nonzero(in_map)
        claimed[rows, heard.slot[rows, columns]] = True
        settled = _settled(places, known, params) | holding
        chosen = choose_spot(
            places, valid, known, real & ~holding, tolerance=params.tolerance,
            rivals=nearest_only(known, real, settled=settled),
            claimed=claimed,
            share=params.rule == "share",
            # The study's rule tries the slot a fish went for first (hysteresis), a new fish
            # its rank; sharing ignores the order.
            first=np.where(memory.place >= 0, memory.place, np.minimum(rank, params.count - 1)),
        )  # fmt: skip
        # The map is anchored at the leader: its place is slot 0, whoever else stands near
        # it or flags it (fish that start side by side, or one hidden behind another, may
        # each take themselves for the leader until the flags settle it).
        chosen = np.where(leads, 0, chosen)
    effort = np.zeros(count) if perception.effort is None else perception.effort
    swaps = _Swaps.none(memory)
    if params.rotate_effort and params.flags and not params.is_local:
        swaps = share_effort(
            memory, effort, inbox, heard, slots=slots.shape[0], now=perception.time, params=params
        )
        chosen = np.where(swaps.swap_to >= 0, swaps.swap_to, chosen)
    has_place = chosen != STAY
    target = np.where(has_place[:, None], places[np.arange(count), np.maximum(chosen, 0)], 0.0)
    joined = has_place & (np.linalg.norm(target, axis=1) <= params.tolerance)
    heading = np.full(count, np.nan) if perception.heading is None else perception.heading
    aim, place_vector = lead_aim(
        target,
        heading=heading,
        previous=memory.place_vector,
        elapsed=perception.time - memory.place_time,
        same_place=has_place & (chosen == memory.place),
        lead=params.lead,
    )
    hops = np.where(rank == 0, 0, np.minimum(heard.fewest_hops + 1, NO_HOPS))
    if params.uses_map:
        hops = np.where(has_place & (chosen == 0), 0, hops)
    # Every fish flags at every decision (joined or seeking): a flag shows where its sender
    # is even when nearer fish hide it, and what it holds or seeks.
    sending = np.full(count, params.flags)
    sequence = memory.sequence + sending
    values = np.zeros((count, BROADCAST_WIDTH), dtype=np.int64)
    heading_mdeg = _heading_mdeg(params.orientation)
    for row in np.flatnonzero(sending).tolist():
        flag = FormationFlag(
            FORMATION_SHAPES.index(params.shape),
            int(chosen[row]),
            bool(joined[row]),
            int(hops[row]),
            heading_mdeg,
            int(sequence[row]),
            round(float(effort[row])),
            int(swaps.asking[row]),
        )
        values[row] = flag.values()
    outbox = Outbox(np.full(count, FORMATION_KIND, dtype=np.int64), values, sending)
    after = FormationMemory(
        chosen.astype(np.int64),
        joined,
        sequence.astype(np.int64),
        place_vector,
        perception.time.astype(np.float64),
        swaps.swap_to,
        swaps.swap_from,
        swaps.swap_since,
    )
    # LEDs always lit: a robot's neighbours see it by them, seeking or not. A robot that
    # holds its place flashes them: its driver makes that of the joined flag.
    return after, Steering(aim, np.ones(count, dtype=np.bool_), outbox)


FORMATION = Behavior(
    "formation",
    "take a place in a shape (formation, spacing), flagging it to the others",
    steer_formation,
    fresh_formation_memory,
    formation_params,
    spawn_radius=10 * BODY_LENGTH,
    # A derivative on the distance to go brakes a fish nearing its slot: measured with 15
    # fish (pyramid, 2 Hz, seeds 0–4, lead 2.5 s) 5 of 5 seeds 90 % joined within 30 s,
    # against 4 of 5 without it.
    pid_gains=PidGains(speed=(2.0, 0.0, 1.0)),
    # The homing controller's bang-bang turns overshoot a place: measured with 15 fish
    # (pyramid, 1 Hz, seed 0, 30 s) 27 % joined with homing against 80 % with pid.
    controller="pid",
)


def with_formation(params: FishParams, shape: str) -> FishParams:
    """The fish's parameters with another formation shape: an operator's live switch.
    Parameters of other behaviours come back unchanged. Effort sharing (global maps only)
    pauses while the shape is local.

    Raises:
        ValueError: an unknown shape.
    """
    steering = params.steering
    # By name: parameters that crossed into a worker process carry a copy of the behaviour.
    if params.behavior.name != FORMATION.name or not isinstance(steering, FormationParams):
        return params
    if steering.shape == shape:
        return params
    return dataclasses.replace(params, steering=dataclasses.replace(steering, shape=shape))


def apply_directive(
    params: FishParams, memory: FishMemory, shape: str | None
) -> tuple[FishParams, FishMemory]:
    """The fish's parameters and memory after a formation directive (None: none): a new
    shape forgets the places; anything else leaves both as they are (the same objects)."""
    if shape is None:
        return params, memory
    switched = with_formation(params, shape)
    if switched is params:
        return params, memory
    return switched, switch_memory(memory, switched)


def switch_memory(memory: FishMemory, params: FishParams) -> FishMemory:
    """The memory of fish that switch shape: their places forgotten, their controllers'
    state kept."""
    count = memory.dorsal_on.shape[0]
    return dataclasses.replace(memory, behavior=params.behavior.fresh_memory(count))
