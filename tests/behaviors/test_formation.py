"""The formation behaviour: flags out and in, the agreed leader, and fish that form."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from fishswarm.behaviors.core import FishMemory, Inbox, Perception, decide, inbox_of, take_rows
from fishswarm.behaviors.formation import (
    SWAP_TIMEOUT,
    FormationMemory,
    FormationParams,
    formation_params,
    fresh_formation_memory,
    lead_aim,
    steer_formation,
)
from fishswarm.behaviors.registry import fish_params
from fishswarm.protocols.messages import BROADCAST_KINDS, FORMATION_SHAPES, FormationFlag
from fishswarm.sim.engine import simulate_batch
from fishswarm.sim.scenario import Scenario

FLAG = BROADCAST_KINDS.index("formation")


def _perception(*neighbors: tuple[float, float, float], heading: float = 0.0) -> Perception:
    rows = np.array([neighbors], dtype=np.float64).reshape(1, -1, 3)
    return Perception(
        np.array([1.0]),
        np.array([0.5]),
        rows,
        np.ones(rows.shape[:2], dtype=np.bool_),
        np.zeros((1, 0, 3)),
        np.zeros((1, 0), dtype=np.bool_),
        np.array([heading]),
    )


def test_a_leader_holds_slot_0_and_flags_it() -> None:
    params = FormationParams("column", count=3)
    # Both neighbours behind the fish (the formation faces +x of the tank, the fish too).
    memory, steering = steer_formation(
        fresh_formation_memory(1), _perception((-0.5, 0.0, 0.0), (-0.4, 0.3, 0.0)),
        Inbox.empty(1), params=params,
    )  # fmt: skip
    assert memory.place.tolist() == [0] and memory.joined.tolist() == [True]
    np.testing.assert_array_equal(steering.target, [[0.0, 0.0, 0.0]])
    assert steering.outbox.mask.tolist() == [True] and steering.led.tolist() == [True]
    flag = FormationFlag.from_values(steering.outbox.values[0])
    assert flag == FormationFlag(FORMATION_SHAPES.index("column"), 0, True, 0, 0, 1)
    # Without flags: nothing is broadcast.
    silent = FormationParams("column", count=3, flags=False)
    _, quiet = steer_formation(
        fresh_formation_memory(1), _perception((-0.5, 0.0, 0.0)), Inbox.empty(1), params=silent
    )
    assert not quiet.outbox.mask.any()


def test_a_follower_heads_for_a_slot_behind_the_flagged_leader() -> None:
    params = FormationParams("column", count=3, spacing=0.3, rule="study")
    # The fish faces the tank's +y (heading 90°): the formation's forward (+x of the tank)
    # is to its left (−y in its body frame). The leader, flagged, is 1 m to its left.
    leader_flag = FormationFlag(FORMATION_SHAPES.index("column"), 0, True, 0, 0, 4)
    inbox = inbox_of([[(FLAG, leader_flag.values(), np.array([0.0, -1.0, 0.0]))]])
    perception = _perception((0.0, -1.0, 0.0), heading=math.pi / 2)
    memory, steering = steer_formation(fresh_formation_memory(1), perception, inbox, params=params)
    # Slot 1 is 0.3 m behind the leader along the formation's forward: 0.7 m to the left.
    assert memory.place.tolist() == [1] and memory.joined.tolist() == [False]
    np.testing.assert_allclose(steering.target, [[0.0, -0.7, 0.0]], atol=1e-12)
    # Not there yet: its flag says which slot it seeks, not joined, one hop from the leader;
    # its LEDs stay lit (neighbours see a robot by them, seeking or not).
    assert steering.outbox.mask.tolist() == [True] and steering.led.tolist() == [True]
    sought = FormationFlag.from_values(steering.outbox.values[0])
    assert sought == FormationFlag(FORMATION_SHAPES.index("column"), 1, False, 1, 0, 1)
    # Sharing the free slots instead: the nearest free slot is the last one, 0.6 m behind
    # the leader, 0.4 m to the fish's left.
    shared = FormationParams("column", count=3, spacing=0.3, rule="share")
    memory, steering = steer_formation(fresh_formation_memory(1), perception, inbox, params=shared)
    assert memory.place.tolist() == [2]
    np.testing.assert_allclose(steering.target, [[0.0, -0.4, 0.0]], atol=1e-12)


def test_a_flagged_slot_is_left_to_its_holder() -> None:
    params = FormationParams("column", count=3, spacing=0.3)
    flags = [
        (FLAG, FormationFlag(2, 0, True, 0, 0, 1).values(), np.array([1.0, 0.0, 0.0])),
        (FLAG, FormationFlag(2, 1, True, 1, 0, 1).values(), np.array([0.7, 0.0, 0.0])),
    ]
    perception = _perception((1.0, 0.0, 0.0), (0.7, 0.0, 0.0))
    memory, steering = steer_formation(
        fresh_formation_memory(1), perception, inbox_of([flags]), params=params
    )
    assert memory.place.tolist() == [2]
    np.testing.assert_allclose(steering.target, [[0.4, 0.0, 0.0]], atol=1e-12)


def _led(place: int) -> FormationMemory:
    """The formation memory of one fish whose last place was ``place``."""
    return dataclasses.replace(fresh_formation_memory(1), place=np.array([place]))


def test_a_leader_keeps_the_lead_against_a_fish_that_passes_it_by_less_than_a_spacing() -> None:
    params = FormationParams("column", count=3, spacing=0.3)
    # A follower (its flag: slot 2, one hop from the leader) swims past the leader, 0.1 m
    # ahead of it: the leader stays on slot 0.
    passing = [(FLAG, FormationFlag(2, 2, False, 1, 0, 7).values(), np.array([0.1, 0.05, 0.0]))]
    memory, steering = steer_formation(
        _led(0), _perception((0.1, 0.05, 0.0)), inbox_of([passing]), params=params
    )
    assert memory.place.tolist() == [0]
    np.testing.assert_array_equal(steering.target, [[0.0, 0.0, 0.0]])
    # 0.4 m ahead, more than a spacing: the passer leads now; the fish takes a slot behind
    # it (the nearest free one, slot 1, 0.3 m behind the passer).
    memory, steering = steer_formation(
        _led(0), _perception((0.4, 0.0, 0.0)), Inbox.empty(1), params=params
    )
    assert memory.place.tolist() == [1]
    np.testing.assert_allclose(steering.target, [[0.1, 0.0, 0.0]], atol=1e-12)
    # A fish that did not lead sees the fish ahead as its leader, as the study's rule says,
    # and takes the free slot nearest to it: slot 1, 0.3 m behind the fish ahead.
    memory, steering = steer_formation(
        _led(2), _perception((0.1, 0.05, 0.0)), Inbox.empty(1), params=params
    )
    assert memory.place.tolist() == [1]
    np.testing.assert_allclose(steering.target, [[-0.2, 0.05, 0.0]], atol=1e-12)


def test_a_fish_that_passed_the_flagged_leader_by_less_than_a_spacing_follows_it() -> None:
    params = FormationParams("column", count=3, spacing=0.3)
    leader = [(FLAG, FormationFlag(2, 0, True, 0, 0, 9).values(), np.array([-0.1, 0.0, 0.0]))]
    perception = _perception((-0.1, 0.0, 0.0))
    # It sought slot 1 at its last decision: the leader 0.1 m behind it is still its leader.
    memory, steering = steer_formation(_led(1), perception, inbox_of([leader]), params=params)
    assert memory.place.tolist() == [1]
    np.testing.assert_allclose(steering.target, [[-0.4, 0.0, 0.0]], atol=1e-12)
    flag = FormationFlag.from_values(steering.outbox.values[0])
    assert flag.hops == 1
    # A fish that led at its last decision yields only to a flagged leader ahead of it: two
    # fish that each took themselves for the leader settle it, the one ahead keeps it.
    memory, _ = steer_formation(_led(0), perception, inbox_of([leader]), params=params)
    assert memory.place.tolist() == [0]
    # Beyond a spacing behind, the flagged leader is no one's leader but its own.
    far = [(FLAG, FormationFlag(2, 0, True, 0, 0, 9).values(), np.array([-0.5, 0.0, 0.0]))]
    memory, _ = steer_formation(
        _led(1), _perception((-0.5, 0.0, 0.0)), inbox_of([far]), params=params
    )
    assert memory.place.tolist() == [0]


def test_a_leader_holds_slot_0_even_with_a_fish_right_behind_it() -> None:
    # Two fish started 3 cm apart, the other within the tolerance of slot 0: the one ahead
    # leads, and slot 0 is where it stands (the map is anchored at it), not a place to share
    # out; nor does the other's flag for slot 0 (it took itself for the leader) take it.
    params = FormationParams("column", count=3, spacing=0.3)
    twin = [(FLAG, FormationFlag(2, 0, True, 0, 0, 1).values(), np.array([-0.03, 0.0, 0.0]))]
    for memory, inbox in ((fresh_formation_memory(1), Inbox.empty(1)), (_led(0), inbox_of([twin]))):
        memory, steering = steer_formation(
            memory, _perception((-0.03, 0.0, 0.0)), inbox, params=params
        )
        assert memory.place.tolist() == [0] and memory.joined.tolist() == [True]
        np.testing.assert_array_equal(steering.target, [[0.0, 0.0, 0.0]])


def test_stars_take_places_on_the_star_map_behind_the_leader() -> None:
    from fishswarm.formations.lattice import star_map

    params = FormationParams("trigonal-planar", count=15, spacing=0.25)
    assert params.uses_map and params.is_local
    # The flagged leader 1 m ahead; the fish is alone with it: it takes the free place
    # nearest to it, by the star map laid behind the leader.
    leader = [(FLAG, FormationFlag(7, 0, True, 0, 0, 3).values(), np.array([1.0, 0.0, 0.0]))]
    memory, steering = steer_formation(
        fresh_formation_memory(1), _perception((1.0, 0.0, 0.0)), inbox_of([leader]),
        params=params,
    )  # fmt: skip
    places = np.array([1.0, 0.0, 0.0]) + star_map(15, spacing=0.25)
    nearest = int(np.argmin(np.linalg.norm(places, axis=1)))
    assert memory.place.tolist() == [nearest]
    np.testing.assert_allclose(steering.target[0], places[nearest], atol=1e-12)
    # With the neighbours' rule it has no map, and one neighbour makes no star: it stays.
    chasing = dataclasses.replace(params, local_rule="neighbors")
    assert not chasing.uses_map
    with pytest.raises(ValueError, match="no map"):
        chasing.slots()
    memory, steering = steer_formation(
        fresh_formation_memory(1), _perception((1.0, 0.0, 0.0)), inbox_of([leader]),
        params=chasing,
    )  # fmt: skip
    assert memory.place.tolist() == [-1]
    np.testing.assert_array_equal(steering.target, [[0.0, 0.0, 0.0]])


def test_an_unknown_local_rule_is_refused() -> None:
    with pytest.raises(ValueError, match="local rule must be one of lattice, neighbors"):
        FormationParams("trigonal-planar", count=4, local_rule="nearest")


def test_effort_sharing_on_a_local_shape_is_refused_not_ignored() -> None:
    from fishswarm.behaviors.formation import formation_params, with_formation

    asked = {"formation": "trigonal-planar", "fish": 4, "rotate_effort": True}
    with pytest.raises(ValueError, match="trigonal-planar is a local shape"):
        formation_params(asked)
    assert formation_params({**asked, "formation": "column"}).rotate_effort
    # A live switch to a local shape pauses the sharing instead: the fish go on.
    params = fish_params({"behavior": "formation", **asked, "formation": "column"})
    switched = with_formation(params, "triangle")
    assert isinstance(switched.steering, FormationParams)
    assert switched.steering.shape == "triangle" and switched.steering.rotate_effort


def test_two_fish_form_a_column_in_the_batch_engine() -> None:
    # From 1.4 m apart: within 30 s the follower holds its slot 0.3 m behind the leader
    # (within the tolerance, 0.075 m, give or take the 1 Hz controller's overshoot).
    scenario = Scenario(
        fish=2, behavior="formation", formation="column", duration=40, seed=1,
        spawn_region="tank", controller="pid", control_period=0.5,
    )  # fmt: skip
    trajectory = simulate_batch(scenario)
    gap = np.linalg.norm(trajectory.position[:, 0] - trajectory.position[:, 1], axis=1)
    late = gap[trajectory.t >= 30.0]
    assert gap[0] > 1.0
    assert np.abs(late - 0.3).max() < 0.075


@pytest.mark.parametrize(
    ("shape", "rule"),
    [
        ("pyramid", "lattice"),
        ("triangle", "lattice"),
        ("trigonal-planar", "lattice"),
        ("trigonal-planar", "neighbors"),
        ("tetrahedron", "lattice"),
        ("tetrahedron", "neighbors"),
    ],
)
def test_formation_fish_decide_alone_as_in_a_school(shape: str, rule: str) -> None:
    params = fish_params(
        {
            "behavior": "formation", "formation": shape, "fish": 6, "local_rule": rule,
            "tank": (1.78, 1.78, 1.17),
        }
    )  # fmt: skip
    rng = np.random.default_rng(3)
    neighbors = rng.normal(0, 0.5, (4, 5, 3))
    mask = np.ones((4, 5), dtype=np.bool_)
    perception = Perception(
        np.ones(4), np.full(4, 0.5), neighbors, mask, np.zeros((4, 0, 3)),
        np.zeros((4, 0), bool), rng.uniform(-3, 3, 4),
    )  # fmt: skip
    memory = FishMemory.fresh(params, 4)
    _, together = decide(memory, perception, Inbox.empty(4), params=params)
    for fish in range(4):
        alone = take_rows(perception, np.array([fish]))
        _, single = decide(FishMemory.fresh(params, 1), alone, Inbox.empty(1), params=params)
        np.testing.assert_array_equal(single.fins[0], together.fins[fish])
        np.testing.assert_array_equal(single.outbox.values[0], together.outbox.values[fish])


def test_a_school_switched_to_another_shape_re_forms() -> None:
    from fishswarm.formations.maps import target_map
    from fishswarm.formations.metrics import shape_error

    # A pyramid for 30 s, then a diamond (as an operator would ask) for 30 s more.
    scenario = Scenario(
        fish=15, behavior="formation", formation="pyramid", duration=60, seed=1,
        spawn_radius=0.4, spacing=0.25, controller="pid", control_period=0.5,
        switch_formation="diamond", switch_at=30.0,
    )  # fmt: skip
    trajectory = simulate_batch(scenario)

    def error(tick: int, shape: str) -> float:
        target = target_map(shape, 15, spacing=0.25)
        return shape_error(trajectory.position[tick], target, tolerance=0.0625)[0]

    assert error(60, "pyramid") < 0.5 * error(60, "diamond")  # formed as asked first
    assert error(120, "diamond") < 0.5 * error(120, "pyramid")  # then re-formed
    assert error(120, "diamond") < 0.0625


def test_with_formation_leaves_other_behaviours_alone() -> None:
    from fishswarm.behaviors.formation import with_formation

    other = fish_params({"behavior": "aggregation", "tank": (1.78, 1.78, 1.17)})
    assert with_formation(other, "diamond") is other
    formation = fish_params(
        {"behavior": "formation", "formation": "pyramid", "tank": (1.78, 1.78, 1.17)}
    )
    assert with_formation(formation, "pyramid") is formation
    assert with_formation(formation, "diamond").steering.shape == "diamond"
    # As a worker process receives them: a copy, whose behaviour is not the same object.
    import pickle

    copied = pickle.loads(pickle.dumps(formation))
    assert with_formation(copied, "diamond").steering.shape == "diamond"


def test_a_fish_closing_on_its_place_aims_short_of_it_by_its_drift() -> None:
    # Drawn on paper: the place was 0.5 m ahead (+x of the tank) half a second ago and is
    # 0.4 m ahead now, so the fish closes at 0.2 m/s; with a 2.5 s lead it would drift
    # 0.5 m, past the place by 0.1 m: it aims 0.1 m behind itself, and brakes.
    previous = np.array([[0.5, 0.0, 0.0], [0.0, 0.5, 0.0], [0.5, 0.0, 0.0], [0.5, 0.0, 0.0]])
    target = np.array([[0.4, 0.0, 0.0], [0.4, 0.0, 0.0], [0.4, 0.0, 0.0], [0.4, 0.0, 0.0]])
    # Fish 1 faces the tank's +y: its place, 0.4 m ahead, lies at +y of the tank. Fish 2
    # has no compass; fish 3 sought another place before.
    heading = np.array([0.0, math.pi / 2, math.nan, 0.0])
    aim, place = lead_aim(
        target, heading=heading, previous=previous, elapsed=np.full(4, 0.5),
        same_place=np.array([True, True, True, False]), lead=2.5,
    )  # fmt: skip
    np.testing.assert_allclose(aim[0], [-0.1, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(aim[1], [-0.1, 0.0, 0.0], atol=1e-12)
    np.testing.assert_array_equal(aim[2:], target[2:])
    np.testing.assert_allclose(place[1], [0.0, 0.4, 0.0], atol=1e-12)
    assert np.isnan(place[2]).all()
    # A fish that holds still on the way aims at the place itself.
    still, _ = lead_aim(
        target[:1], heading=np.zeros(1), previous=target[:1], elapsed=np.full(1, 0.5),
        same_place=np.ones(1, dtype=np.bool_), lead=2.5,
    )  # fmt: skip
    np.testing.assert_array_equal(still, target[:1])


@pytest.mark.parametrize("shape", ["pyramid", "diamond", "trigonal-planar"])
def test_fifteen_fish_hold_their_places(shape: str) -> None:
    from fishswarm.study.metrics import formation_target_of

    scenario = Scenario(
        fish=15, behavior="formation", formation=shape, duration=30, seed=0,
        spawn_radius=0.4, spacing=0.25, controller="pid", control_period=0.5,
    )  # fmt: skip
    trajectory = simulate_batch(scenario)
    target = formation_target_of(scenario)
    assert target is not None
    final = target.metrics(trajectory.position[-1])
    # Measured: 100 % joined, 0.023 m (pyramid), 0.024 m (diamond) and 0.012 m (stars,
    # each fish's group against the ideal star); without the lead the pyramid ends at 67 %
    # and 0.067 m.
    assert final["joined_fraction"] >= 0.9 and final["shape_error"] <= 0.25 * 0.25
    np.testing.assert_array_less(np.linalg.norm(trajectory.velocity[-1], axis=1), 0.05)


def _holding(place: int, *, swap_to: int = -1, since: float = math.nan) -> FormationMemory:
    """The formation memory of one fish that holds ``place`` (joined)."""
    fresh = fresh_formation_memory(1)
    return dataclasses.replace(
        fresh,
        place=np.array([place]),
        joined=np.array([True]),
        swap_to=np.array([swap_to]),
        swap_from=np.array([-1 if swap_to < 0 else place]),
        swap_since=np.array([since]),
    )


def _flag(slot: int, joined: bool, *, effort: int = 0, swap: int = -1) -> np.ndarray:
    return FormationFlag(
        FORMATION_SHAPES.index("column"), slot, joined, 0, 0, 1, effort, swap
    ).values()


def _tired(perception: Perception, effort: float) -> Perception:
    return dataclasses.replace(perception, time=np.array([100.0]), effort=np.array([effort]))


def test_effort_sharing_by_a_handshake_of_flags_drawn_on_paper() -> None:
    # A column (spacing 0.3 m, margin 40) facing +x: L leads at slot 0; T holds slot 1,
    # 0.3 m behind it; R holds slot 2, 0.3 m behind T; U holds slot 3, 0.6 m behind T: too
    # far to be T's neighbour (1.5 spacings).
    params = FormationParams("column", count=4, spacing=0.3, rotate_effort=True, effort_margin=40)
    around = _tired(_perception((0.3, 0.0, 0.0), (-0.3, 0.0, 0.0), (-0.6, 0.0, 0.0)), 100.0)
    heard = inbox_of([[
        (FLAG, _flag(0, True, effort=0), np.array([0.3, 0.0, 0.0])),
        (FLAG, _flag(2, True, effort=50), np.array([-0.3, 0.0, 0.0])),
        (FLAG, _flag(3, True, effort=10), np.array([-0.6, 0.0, 0.0])),
    ]])  # fmt: skip
    # 1. Ask: T spent 50 more than R (more than the margin): it flags R's slot, and stays.
    # L rested more, but the map is anchored at its leader: slot 0 is not swapped.
    memory, steering = steer_formation(_holding(1), around, heard, params=params)
    asking = FormationFlag.from_values(steering.outbox.values[0])
    assert (asking.slot, asking.joined, asking.swap, asking.effort) == (1, True, 2, 100)
    assert memory.swap_to.tolist() == [-1]
    np.testing.assert_allclose(steering.target, [[0.0, 0.0, 0.0]], atol=1e-12)
    # Within the margin, nobody is asked.
    _, calm = steer_formation(_holding(1), _tired(around, 80.0), heard, params=params)
    assert FormationFlag.from_values(calm.outbox.values[0]).swap == -1
    # 2. Agree: R hears T's request (T 0.3 m ahead of it, L 0.6 m) and heads for slot 1,
    # flagging that it seeks it and gives up slot 2.
    at_r = _tired(_perception((0.3, 0.0, 0.0), (0.6, 0.0, 0.0)), 50.0)
    request = inbox_of([[(FLAG, asking.values(), np.array([0.3, 0.0, 0.0]))]])
    memory_r, steering_r = steer_formation(_holding(2), at_r, request, params=params)
    agreed = FormationFlag.from_values(steering_r.outbox.values[0])
    assert (agreed.slot, agreed.joined, agreed.swap) == (1, False, 2)
    assert (memory_r.swap_to.tolist(), memory_r.swap_from.tolist()) == ([1], [2])
    assert memory_r.swap_since.tolist() == [100.0]
    np.testing.assert_allclose(steering_r.target, [[0.3, 0.0, 0.0]], atol=1e-12)
    # 3. Go: T hears R seek its slot and give up slot 2: it heads for slot 2, 0.3 m behind.
    answer = inbox_of([[(FLAG, agreed.values(), np.array([-0.3, 0.0, 0.0]))]])
    memory_t, steering_t = steer_formation(_holding(1), around, answer, params=params)
    going = FormationFlag.from_values(steering_t.outbox.values[0])
    assert (going.slot, going.joined, going.swap) == (2, False, 1)
    assert memory_t.swap_to.tolist() == [2]
    np.testing.assert_allclose(steering_t.target, [[-0.3, 0.0, 0.0]], atol=1e-12)
    # Without rotation (the default) the same inbox moves nobody.
    still = FormationParams("column", count=4, spacing=0.3)
    _, unmoved = steer_formation(_holding(1), around, answer, params=still)
    np.testing.assert_allclose(unmoved.target, [[0.0, 0.0, 0.0]], atol=1e-12)
    # A seeker offering a slot past the end of T's map (a fish with a larger map, or a
    # forged flag) is not answered: T holds its slot.
    beyond = dataclasses.replace(agreed, swap=40)
    odd = inbox_of([[(FLAG, beyond.values(), np.array([-0.3, 0.0, 0.0]))]])
    memory_odd, steering_odd = steer_formation(_holding(1), around, odd, params=params)
    assert memory_odd.swap_to.tolist() == [-1]
    np.testing.assert_allclose(steering_odd.target, [[0.0, 0.0, 0.0]], atol=1e-12)


def test_the_leader_of_a_map_anchored_at_it_neither_asks_nor_is_asked_to_swap() -> None:
    # The map moves with its leader (slot 0): a leader that left for slot 1 would carry
    # slot 1 along, chase it, and draw the school into a corner of the tank (measured: 15
    # fish in a pyramid, 0 % joined and every pair colliding after 120 s). A tired leader
    # 0.3 m ahead of a rested fish at slot 1 (a column, spacing 0.3 m, margin 40):
    params = FormationParams("column", count=3, spacing=0.3, rotate_effort=True, effort_margin=40)
    behind = _tired(_perception((-0.3, 0.0, 0.0)), 100.0)
    rested = inbox_of([[(FLAG, _flag(1, True, effort=10), np.array([-0.3, 0.0, 0.0]))]])
    _, steering = steer_formation(_holding(0), behind, rested, params=params)
    assert FormationFlag.from_values(steering.outbox.values[0]).swap == -1
    # Asked anyway (a flag from an older fish, or a forged one), it stays.
    asker = _tired(_perception((-0.3, 0.0, 0.0)), 10.0)
    request = inbox_of([[(FLAG, _flag(1, True, effort=100, swap=0), np.array([-0.3, 0, 0]))]])
    memory, steering = steer_formation(_holding(0), asker, request, params=params)
    assert memory.swap_to.tolist() == [-1]
    np.testing.assert_allclose(steering.target, [[0.0, 0.0, 0.0]], atol=1e-12)
    # Behind a station's post slot 0 is a place in the water, not the leader's: it is
    # swapped like any other (the flow tank's formation-energy experiment).
    stationed = dataclasses.replace(params, station=0.2)
    _, steering = steer_formation(_holding(0), behind, rested, params=stationed)
    assert FormationFlag.from_values(steering.outbox.values[0]).swap == 1


def test_a_swap_goes_on_until_the_fish_arrives_or_gives_up_and_then_it_rests() -> None:
    params = FormationParams("column", count=3, spacing=0.3, rotate_effort=True, effort_margin=40)
    here = _tired(_perception((-0.3, 0.0, 0.0)), 100.0)
    rested = inbox_of([[(FLAG, _flag(1, True, effort=10), np.array([-0.3, 0.0, 0.0]))]])
    # Under way (began 10 s ago, not there): it keeps going for slot 2 and asks nothing.
    moving = dataclasses.replace(_holding(1, swap_to=2, since=90.0), joined=np.array([False]))
    memory, steering = steer_formation(moving, here, rested, params=params)
    flag = FormationFlag.from_values(steering.outbox.values[0])
    assert memory.swap_to.tolist() == [2] and (flag.slot, flag.swap) == (2, 1)
    # Not there after SWAP_TIMEOUT (20 s): it gives up; still within SWAP_REST (30 s) of the
    # swap's start, so it does not ask either.
    late = dataclasses.replace(moving, swap_since=np.array([75.0]))
    memory, steering = steer_formation(late, here, rested, params=params)
    assert memory.swap_to.tolist() == [-1]
    assert FormationFlag.from_values(steering.outbox.values[0]).swap == -1
    # Arrived (holds slot 2, joined): the swap is over; it rests.
    arrived = dataclasses.replace(_holding(2, swap_to=2, since=80.0))
    memory, steering = steer_formation(arrived, here, rested, params=params)
    assert memory.swap_to.tolist() == [-1] and memory.swap_since.tolist() == [80.0]
    assert FormationFlag.from_values(steering.outbox.values[0]).swap == -1
    # Rested long enough (the swap began 31 s ago): tired again, it asks.
    _, steering = steer_formation(_holding(2, since=69.0), here, rested, params=params)
    assert FormationFlag.from_values(steering.outbox.values[0]).swap == 1


def test_a_fish_that_sees_the_post_anchors_the_map_at_the_station_behind_it() -> None:
    # The post 1 m ahead (+x: the formation's forward, the fish's too); the station is
    # 0.2 m behind it: slot 0 at 0.8 m, slot 1 (a column, spacing 0.3) at 0.5 m.
    params = FormationParams("column", count=2, spacing=0.3, station=0.2, rule="study")
    seen = dataclasses.replace(
        _perception((-0.5, 0.0, 0.0)),
        landmarks=np.array([[[1.0, 0.0, 0.0]]]),
        landmark_mask=np.array([[True]]),
    )
    memory, steering = steer_formation(
        fresh_formation_memory(1), seen, Inbox.empty(1), params=params
    )
    assert memory.place.tolist() == [0]
    np.testing.assert_allclose(steering.target, [[0.8, 0.0, 0.0]], atol=1e-12)
    # Not seeing the post, it anchors the map at the leader it sees (itself, ahead of all).
    _, blind = steer_formation(
        fresh_formation_memory(1), _perception((-0.5, 0.0, 0.0)), Inbox.empty(1), params=params
    )
    np.testing.assert_allclose(blind.target, [[0.0, 0.0, 0.0]], atol=1e-12)


def test_with_a_station_holding_slot_0_is_no_claim_to_lead() -> None:
    # A fish that sought the station (slot 0) at its last decision and no longer sees the
    # post: a fish 0.2 m ahead of it leads, and it takes slot 1 behind that fish — it does
    # not keep a lead it never had.
    params = FormationParams("column", count=2, spacing=0.3, station=0.5)
    memory, steering = steer_formation(
        _led(0), _perception((0.2, 0.0, 0.0)), Inbox.empty(1), params=params
    )
    assert memory.place.tolist() == [1] and memory.joined.tolist() == [False]
    np.testing.assert_allclose(steering.target, [[-0.1, 0.0, 0.0]], atol=1e-12)
    # Without a station the same fish keeps the lead (less than a spacing behind it).
    plain = dataclasses.replace(params, station=None)
    memory, _ = steer_formation(_led(0), _perception((0.2, 0.0, 0.0)), Inbox.empty(1), params=plain)
    assert memory.place.tolist() == [0]


def test_effort_sharing_fish_decide_alone_as_in_a_school() -> None:
    params = fish_params(
        {"behavior": "formation", "formation": "column", "fish": 4, "spacing": 0.3,
         "rotate_effort": True, "effort_margin": 5.0, "tank": (1.78, 1.78, 1.17)}
    )  # fmt: skip
    rng = np.random.default_rng(5)
    neighbors = np.tile(np.array([[-0.3, 0.0, 0.0], [0.3, 0.0, 0.0]]), (4, 1, 1))
    perception = Perception(
        np.full(4, 50.0), np.full(4, 0.5), neighbors, np.ones((4, 2), dtype=np.bool_),
        np.zeros((4, 0, 3)), np.zeros((4, 0), bool), np.zeros(4),
    )  # fmt: skip
    heard = [
        [(FLAG, _flag(int(rng.integers(0, 4)), bool(rng.integers(0, 2)),
                      effort=int(rng.integers(0, 40)), swap=int(rng.integers(-1, 4))),
          neighbors[0, int(rng.integers(0, 2))]) for _ in range(3)]
        for _ in range(4)
    ]  # fmt: skip
    memory = FishMemory.fresh(params, 4)
    memory = dataclasses.replace(
        memory,
        behavior=dataclasses.replace(
            memory.behavior, place=np.array([0, 1, 2, 3]), joined=np.ones(4, dtype=np.bool_)
        ),
        effort=np.array([60.0, 10.0, 30.0, 45.0]),
        last_time=np.full(4, 49.5),
    )
    _, together = decide(memory, perception, inbox_of(heard), params=params)
    for fish in range(4):
        rows = np.array([fish])
        _, single = decide(
            take_rows(memory, rows), take_rows(perception, rows), inbox_of([heard[fish]]),
            params=params,
        )  # fmt: skip
        np.testing.assert_array_equal(single.fins[0], together.fins[fish])
        np.testing.assert_array_equal(single.outbox.values[0], together.outbox.values[fish])
    # Some of them asked, agreed or went (the case is not idle).
    assert (together.outbox.values[:, 7] > 0).any()


def test_a_fish_exactly_the_margin_more_tired_does_not_ask_one_more_does() -> None:
    # T holds slot 1 behind the leader (0.3 m ahead), with R (effort 50) at slot 2, 0.3 m
    # behind it; margin 40.
    params = FormationParams("column", count=3, spacing=0.3, rotate_effort=True, effort_margin=40)
    around = _perception((0.3, 0.0, 0.0), (-0.3, 0.0, 0.0))
    heard = inbox_of([[(FLAG, _flag(2, True, effort=50), np.array([-0.3, 0.0, 0.0]))]])
    for effort, swap in ((90.0, -1), (91.0, 2)):
        _, steering = steer_formation(_holding(1), _tired(around, effort), heard, params=params)
        assert FormationFlag.from_values(steering.outbox.values[0]).swap == swap


def test_the_flag_carries_the_orientation_in_millidegrees() -> None:
    params = FormationParams("column", count=3, orientation=math.pi / 2)
    _, steering = steer_formation(
        fresh_formation_memory(1), _perception((-0.5, 0.0, 0.0)), Inbox.empty(1), params=params
    )
    assert FormationFlag.from_values(steering.outbox.values[0]).heading_mdeg == 90_000


def test_a_negative_lead_is_refused() -> None:
    with pytest.raises(ValueError, match="lead must be a time of 0 s or more"):
        FormationParams("pyramid", count=15, lead=-1.0)


@pytest.mark.parametrize(("leader_y", "joined"), [(-0.38, False), (-0.37, True)])
def test_a_fish_has_joined_only_within_the_tolerance_of_its_place(
    leader_y: float, joined: bool
) -> None:
    # As the follower above (facing +y, the formation forward to its left), its slot 0.3 m
    # behind the leader: 0.08 m away (outside the tolerance 0.075) or 0.07 m (inside).
    params = FormationParams("column", count=3, spacing=0.3, rule="study")
    leader_flag = FormationFlag(FORMATION_SHAPES.index("column"), 0, True, 0, 0, 4)
    inbox = inbox_of([[(FLAG, leader_flag.values(), np.array([0.0, leader_y, 0.0]))]])
    perception = _perception((0.0, leader_y, 0.0), heading=math.pi / 2)
    memory, steering = steer_formation(fresh_formation_memory(1), perception, inbox, params=params)
    assert memory.place.tolist() == [1] and memory.joined.tolist() == [joined]
    # Its flag says so (on a robot: the LEDs flash), and its LEDs stay lit either way.
    assert FormationFlag.from_values(steering.outbox.values[0]).joined is joined
    assert steering.led.tolist() == [True]


@pytest.mark.parametrize(("seen_x", "merged"), [(1.1, False), (1.03, True)])
def test_a_seen_fish_where_a_flag_shows_its_sender_is_that_sender(
    seen_x: float, merged: bool
) -> None:
    # A flag's sender appears 1 m ahead; a fish is seen 0.1 m from there (two fish: more
    # than half the tolerance 0.075 apart) or 0.03 m (one fish, which holds its place).
    from fishswarm.behaviors.formation import _heard_flags, _with_senders

    params = FormationParams("column", count=3, spacing=0.3)
    inbox = inbox_of([[(FLAG, _flag(1, True), np.array([1.0, 0.0, 0.0]))]])
    neighbors = np.array([[[seen_x, 0.0, 0.0], [2.0, 0.0, 0.0]]])
    mask = np.ones((1, 2), dtype=np.bool_)
    _, real, holding = _with_senders(neighbors, mask, inbox, _heard_flags(inbox, params), params)
    assert real.tolist() == [[True, True, not merged]]
    assert holding.tolist() == [[merged, False, not merged]]


def test_a_seen_fish_that_flags_by_light_holds_no_slot() -> None:
    # A flag by light says its sender holds its place, and names no slot: the fish seen
    # where it shows its sender (0.03 m off) is that sender, and stands where it is seen,
    # as any fish seen does; it claims no slot, so it takes part in sharing them out.
    from fishswarm.behaviors.formation import _heard_flags, _with_senders, flag_by_light

    params = FormationParams("column", count=3, spacing=0.3)
    light = flag_by_light(FormationFlag.from_values(_flag(1, True))).values()
    inbox = inbox_of([[(FLAG, light, np.array([1.0, 0.0, 0.0]))]])
    neighbors = np.array([[[1.03, 0.0, 0.0], [2.0, 0.0, 0.0]]])
    mask = np.ones((1, 2), dtype=np.bool_)
    _, real, holding = _with_senders(neighbors, mask, inbox, _heard_flags(inbox, params), params)
    assert real.tolist() == [[True, True, False]]
    assert holding.tolist() == [[False, False, False]]


def test_flags_naming_no_slot_or_one_past_the_map_claim_nothing() -> None:
    """A column of 3 (slots 1.0, 0.7 and 0.4 m ahead of the fish, behind a leader flagged 1 m
    ahead): flags, joined, for slot −1 and slot 40 (a larger map's, or forged) from fish
    far to the side must neither claim a slot nor fail; the fish takes the nearest free
    slot, 2, as with the leader's flag alone."""
    params = FormationParams("column", count=3, spacing=0.3)
    leader = (FLAG, FormationFlag(2, 0, True, 0, 0, 1).values(), np.array([1.0, 0.0, 0.0]))
    odd = [
        (FLAG, FormationFlag(2, -1, True, 1, 0, 1).values(), np.array([0.0, 3.0, 0.0])),
        (FLAG, FormationFlag(2, 40, True, 1, 0, 1).values(), np.array([0.0, -3.0, 0.0])),
    ]
    seen = _perception((1.0, 0.0, 0.0), (0.0, 3.0, 0.0), (0.0, -3.0, 0.0))
    alone, _ = steer_formation(
        fresh_formation_memory(1), _perception((1.0, 0.0, 0.0)), inbox_of([[leader]]),
        params=params,
    )  # fmt: skip
    memory, steering = steer_formation(
        fresh_formation_memory(1), seen, inbox_of([[leader, *odd]]), params=params
    )
    assert alone.place.tolist() == memory.place.tolist() == [2]
    np.testing.assert_allclose(steering.target, [[0.4, 0.0, 0.0]], atol=1e-12)


def test_a_passer_just_beyond_a_spacing_takes_the_lead() -> None:
    # 0.31 m ahead of the leader, a spacing (0.3 m) and a little: it leads now, and the old
    # leader takes slot 1, 0.3 m behind it: 0.01 m ahead of itself.
    params = FormationParams("column", count=3, spacing=0.3)
    memory, steering = steer_formation(
        _led(0), _perception((0.31, 0.0, 0.0)), Inbox.empty(1), params=params
    )
    assert memory.place.tolist() == [1]
    np.testing.assert_allclose(steering.target, [[0.01, 0.0, 0.0]], atol=1e-12)


def test_a_swap_not_done_in_exactly_its_timeout_is_given_up() -> None:
    params = FormationParams("column", count=3, spacing=0.3, rotate_effort=True, effort_margin=40)
    here = _tired(_perception((-0.3, 0.0, 0.0)), 100.0)
    rested = inbox_of([[(FLAG, _flag(1, True, effort=10), np.array([-0.3, 0.0, 0.0]))]])
    since = 100.0 - SWAP_TIMEOUT
    moving = dataclasses.replace(_holding(1, swap_to=2, since=since), joined=np.array([False]))
    memory, _ = steer_formation(moving, here, rested, params=params)
    assert memory.swap_to.tolist() == [-1]


def test_no_lead_without_time_between_the_decisions() -> None:
    # The same place seen twice at one time: no velocity can be told, so the fish aims at
    # the place itself (not at a place pushed to infinity by a division by zero).
    target = np.array([[0.5, 0.1, 0.0]])
    aim, _ = lead_aim(
        target, heading=np.array([0.0]), previous=np.array([[0.6, 0.1, 0.0]]),
        elapsed=np.array([0.0]), same_place=np.array([True]), lead=2.0,
    )  # fmt: skip
    np.testing.assert_array_equal(aim, target)


def test_formation_settings_take_a_quarter_spacing_tolerance_and_refuse_a_zero_one() -> None:
    params = formation_params({"formation": "column", "spacing": 0.4, "fish": 5})
    assert params.tolerance == pytest.approx(0.1) and params.count == 5
    assert formation_params({"tolerance": 0.05}).tolerance == 0.05
    with pytest.raises(ValueError, match="spacing and tolerance must be positive"):
        FormationParams("column", count=3, tolerance=0.0)
