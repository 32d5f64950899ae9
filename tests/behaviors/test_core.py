"""The fish core: one decision shape for every behaviour, batch == loop of single fish."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fishswarm.behaviors.conformance import WIDTH, alone, random_inbox, random_perception
from fishswarm.behaviors.core import (
    Behavior,
    BehaviorError,
    FishMemory,
    FishParams,
    Inbox,
    Outbox,
    Perception,
    Steer,
    Steering,
    decide,
    inbox_of,
    no_memory,
    pad_rows,
    put_rows,
    stack_rows,
    steady,
    take_rows,
)
from fishswarm.behaviors.registry import BEHAVIORS, behavior_named, fish_params, register
from fishswarm.behaviors.replica import STUDY_SCALE, replica_motion
from fishswarm.learning.arena import Arena
from tests.behaviors import example_plugin
from tests.behaviors.signal_behavior import SIGNAL, registered

TANK = (1.78, 1.78, 1.17)


def _settings(behavior: str, controller: str, model: Path) -> dict[str, object]:
    return {
        "behavior": behavior,
        "controller": controller,
        "tank": TANK,
        "target_distance": None,
        "orbit_radius": 0.45,
        "model": str(model),
        "control_period": 1.0,
    }


@pytest.fixture(scope="module")
def model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("model") / "best_replica.npz"
    weights = np.random.default_rng(0).normal(0, 1, 21)
    np.savez(path, weights=weights, settings='{"behavior": "aggregation"}')
    return path


@pytest.mark.parametrize("controller", ["homing", "pid"])
@pytest.mark.parametrize("behavior", [*BEHAVIORS, SIGNAL.name, "nearest"])
def test_batch_equals_loop_of_single_fish(controller: str, behavior: str, model: Path) -> None:
    registered()
    example_plugin.registered()  # the example package's, as another package would add one
    params = fish_params(_settings(behavior, controller, model))
    rng = np.random.default_rng(8)
    count = 9
    memory = FishMemory.fresh(params, count)
    for step in range(3):
        # Jittered decision times, so the pid loops integrate over uneven periods.
        perception = random_perception(rng, count, 1.0 + step + rng.uniform(-0.2, 0.2), WIDTH)
        inbox = random_inbox(rng, count)
        next_memory, decision = decide(memory, perception, inbox, params=params)
        for i in range(count):
            own, own_inbox = alone(perception, inbox, i)
            single_memory, single = decide(
                take_rows(memory, np.array([i])), own, own_inbox, params=params
            )
            np.testing.assert_array_equal(single.fins[0], decision.fins[i])
            assert single.led[0] == decision.led[i]
            np.testing.assert_array_equal(single.outbox.values[0], decision.outbox.values[i])
            assert single.outbox.mask[0] == decision.outbox.mask[i]
            np.testing.assert_array_equal(
                single_memory.last_time, take_rows(next_memory, np.array([i])).last_time
            )
        memory = next_memory


def test_pid_integrates_over_the_real_elapsed_time() -> None:
    params = fish_params({"behavior": "aggregation", "controller": "pid", "tank": TANK})
    ahead = Perception(
        np.array([0.0]),
        np.array([0.5]),
        np.array([[[1.0, 0.0, 0.1]]]),
        np.ones((1, 1), bool),
        np.zeros((1, 0, 3)),
        np.zeros((1, 0), bool),
    )
    first, _ = decide(FishMemory.fresh(params, 1), ahead, Inbox.empty(1), params=params)
    # The first decision counts one nominal period (1 s); the depth error integrates to
    # error × 1 s. A second decision 0.25 s later adds error × 0.25 s, not × 1 s.
    depth_error = first.pid.previous_error[0, 0]
    assert first.pid.integral[0, 0] == pytest.approx(depth_error * 1.0)
    later = Perception(np.array([0.25]), *[getattr(ahead, f) for f in ("depth", "neighbors",
        "neighbor_mask", "landmarks", "landmark_mask")])  # fmt: skip
    second, _ = decide(first, later, Inbox.empty(1), params=params)
    assert second.pid.integral[0, 0] == pytest.approx(depth_error * 1.25)
    assert second.last_time.tolist() == [0.25]


def test_dispersing_fish_turns_away_from_a_neighbour_ahead() -> None:
    # A neighbour 1 m ahead, 0.1 m left: dispersion pushes the target behind to the right
    # (bearing ≈ 174°), so the homing controller turns with the left pectoral at
    # min(1, 0.6 + 174/180) = 1 and keeps the caudal off; LEDs lit, nothing broadcast.
    params = fish_params({"behavior": "dispersion", "tank": TANK})
    perception = Perception(
        np.array([1.0]),
        np.array([0.5]),
        np.array([[[1.0, -0.1, 0.0]]]),
        np.ones((1, 1), bool),
        np.zeros((1, 0, 3)),
        np.zeros((1, 0), bool),
    )
    _, decision = decide(FishMemory.fresh(params, 1), perception, Inbox.empty(1), params=params)
    assert decision.fins.tolist() == [[0.0, 0.0, 1.0, 0.0]]
    assert decision.led.tolist() == [True]
    assert not decision.outbox.mask.any()


def test_replica_holds_its_first_depth(model: Path) -> None:
    params = fish_params({"behavior": "replica", "model": str(model), "tank": TANK})
    alone = Perception(
        np.array([0.0]),
        np.array([0.5]),
        np.zeros((1, 0, 3)),
        np.zeros((1, 0), bool),
        np.zeros((1, 0, 3)),
        np.zeros((1, 0), bool),
    )
    memory, _ = decide(FishMemory.fresh(params, 1), alone, Inbox.empty(1), params=params)
    assert memory.behavior.hold_depth.tolist() == [0.5]
    # Now 5 cm shallower: the target points down (z > 0), so the dorsal fin comes on.
    shallower = Perception(np.array([1.0]), np.array([0.45]), *[getattr(alone, f) for f in (
        "neighbors", "neighbor_mask", "landmarks", "landmark_mask")])  # fmt: skip
    memory, decision = decide(memory, shallower, Inbox.empty(1), params=params)
    assert decision.fins[0, 1] == 1.0
    assert memory.behavior.hold_depth.tolist() == [0.5]


def test_replica_motion_by_hand() -> None:
    # Hidden weights 0 → hidden 0.5; output biases +50, 0, +50 → outputs (1, 0.5, 1):
    # direction (+1, 0), speed 9 per neighbour; two neighbours sum to 18, capped at 9 units/s:
    # 9 × 1 s × 1.78/300 m = 0.0534 m straight ahead (the study's replica).
    weights = np.zeros(21)
    weights[18:21] = [50.0, 0.0, 50.0]
    neighbors = np.array([[[0.3, 0.1, 0.0], [-0.2, 0.2, 0.1], [9.0, 9.0, 0.0]]])
    mask = np.array([[True, True, False]])
    study = Arena()
    motion = replica_motion(neighbors, mask, weights=weights, arena=study)
    np.testing.assert_allclose(motion, [[9 * STUDY_SCALE, 0.0]], atol=1e-15)
    far = replica_motion(
        np.array([[[0.7, 0.0, 0.0]]]), np.ones((1, 1), bool), weights=weights, arena=study
    )
    np.testing.assert_array_equal(far, [[0.0, 0.0]])
    # A reciprocal replica pushes the other way for a neighbour on the other side: a push
    # every neighbour gives alike cancels, and the fish stays.
    still = replica_motion(neighbors, mask, weights=weights, arena=Arena(replica="reciprocal"))
    np.testing.assert_array_equal(still, [[0.0, 0.0]])
    # An isotropic replica turns the same answer to each neighbour's bearing: 9 towards each
    # of the two, (0.3, 0.1)/0.316 and (−0.2, 0.2)/0.283, summing to 9 × (0.242, 1.023),
    # longer than 9, so capped: 9 units/s towards (0.230, 0.973), between the two.
    toward = replica_motion(neighbors, mask, weights=weights, arena=Arena(replica="isotropic"))
    total = np.array([0.3, 0.1]) / np.hypot(0.3, 0.1) + np.array([-0.2, 0.2]) / np.hypot(0.2, 0.2)
    expected = 9 * STUDY_SCALE * total / np.linalg.norm(total)
    np.testing.assert_allclose(toward, [expected], rtol=1e-12)
    np.testing.assert_allclose(expected / (9 * STUDY_SCALE), [0.2298, 0.9733], atol=1e-4)


def test_a_replica_runs_with_the_input_scale_it_was_learned_with(tmp_path: Path) -> None:
    import json

    weights = np.random.default_rng(3).normal(0, 1, 21)
    for name, arena, scale in (
        ("new.npz", {"side": 300.0, "replica_input_scale": 40.0}, 40.0),
        ("old.npz", {"side": 300.0}, 100.0),  # written before the scale was a setting
    ):
        path = tmp_path / name
        np.savez(path, weights=weights, settings=np.array(json.dumps({"arena": arena})))
        params = fish_params({"behavior": "replica", "model": str(path), "tank": TANK})
        assert params.steering.arena.replica_input_scale == scale
    # Seen over 100 or over 40, one neighbour 0.5 m off moves the fish differently.
    neighbors, mask = np.array([[[0.5, 0.0, 0.0]]]), np.ones((1, 1), bool)
    old = fish_params({"behavior": "replica", "model": str(tmp_path / "old.npz"), "tank": TANK})
    new = fish_params({"behavior": "replica", "model": str(tmp_path / "new.npz"), "tank": TANK})
    assert not np.allclose(
        replica_motion(neighbors, mask, weights=weights, arena=old.steering.arena),
        replica_motion(neighbors, mask, weights=weights, arena=new.steering.arena),
    )


def test_bad_behaviours_and_parameters_are_explained(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="behavior must be one of dispersion, aggregation"):
        behavior_named("schooling")
    with pytest.raises(ValueError, match="needs a learned model"):
        fish_params({"behavior": "replica", "tank": TANK})
    with pytest.raises(ValueError, match="orbit radius must be positive"):
        fish_params({"behavior": "orbit", "orbit_radius": -1.0, "tank": TANK})
    with pytest.raises(ValueError, match="controller must be one of"):
        FishParams(behavior_named("orbit"), None, controller="bang-bang")
    with pytest.raises(ValueError, match="registered already"):
        register(SIGNAL.__class__(**{**SIGNAL.__dict__, "name": "orbit"}))


def test_rows_are_taken_and_put_back_through_nested_memory() -> None:
    params = fish_params({"behavior": "aggregation", "controller": "pid", "tank": TANK})
    memory = FishMemory.fresh(params, 4)
    rows = np.array([1, 3])
    part = take_rows(memory, rows)
    assert part.dorsal_on.shape == (2,) and part.pid.integral.shape == (2, 3)
    changed = dataclasses.replace(
        part, dorsal_on=np.array([True, True]), last_time=np.array([7.0, 8.0])
    )
    whole = put_rows(memory, rows, changed)
    assert whole.dorsal_on.tolist() == [False, True, False, True]
    np.testing.assert_array_equal(whole.last_time, [np.nan, 7.0, np.nan, 8.0])
    assert np.isnan(memory.last_time).all()  # the original is untouched


def test_pad_rows_unstacks_fish_after_fish() -> None:
    stacked = np.arange(9.0).reshape(3, 3)
    neighbors, mask = pad_rows(np.array([2, 0, 1]), stacked)
    assert neighbors.shape == (3, 2, 3)
    assert mask.tolist() == [[True, True], [False, False], [True, False]]
    np.testing.assert_array_equal(neighbors[0], stacked[:2])
    np.testing.assert_array_equal(neighbors[1], np.zeros((2, 3)))
    np.testing.assert_array_equal(neighbors[2], [stacked[2], [0.0, 0.0, 0.0]])
    empty, empty_mask = pad_rows(np.zeros(0, dtype=np.int64), np.zeros((0, 3)))
    assert empty.shape == (0, 0, 3) and empty_mask.shape == (0, 0)


@settings(max_examples=80, deadline=None)
@given(counts=st.lists(st.integers(0, 6), min_size=2, max_size=20), columns=st.integers(1, 4))
def test_stacking_and_padding_rows_undo_each_other(counts: list[int], columns: int) -> None:
    # Against numpy's boolean indexing, the plain statement of both.
    rng = np.random.default_rng(len(counts))
    stacked = rng.normal(size=(sum(counts), 3))
    padded, mask = pad_rows(np.array(counts), stacked)
    expected = np.zeros((len(counts), max(counts), 3))
    expected[np.arange(max(counts)) < np.array(counts)[:, None]] = stacked
    np.testing.assert_array_equal(padded, expected)
    np.testing.assert_array_equal(stack_rows(padded, mask), stacked)
    wide = rng.normal(size=(len(counts), max(counts), columns))
    np.testing.assert_array_equal(stack_rows(wide, mask), wide[mask])


def test_inbox_of_pads_what_each_fish_heard() -> None:
    inbox = inbox_of([[(1, np.array([4, 5]), np.array([0.1, 0.2, 0.3]))], []])
    assert inbox.mask.tolist() == [[True], [False]]
    assert inbox.values[0, 0].tolist() == [4, 5, 0, 0, 0, 0, 0, 0]
    assert inbox.kind.tolist() == [[1], [0]]
    np.testing.assert_array_equal(inbox.sender[0, 0], [0.1, 0.2, 0.3])


def test_the_rules_a_fish_reports_name_its_fish_side_study_code_switches() -> None:
    from fishswarm.behaviors.registry import rules_of
    from fishswarm.sim.scenario import Scenario

    assert rules_of(Scenario().fish_params()) == "paper"
    assert rules_of(Scenario(profile="study-code").fish_params()) == "lennard-jones,homing"
    assert rules_of(Scenario(study_code=("homing", "drag")).fish_params()) == "homing"
    # Orbiting has no Lennard-Jones force: only the homing branch applies.
    orbit = Scenario(behavior="orbit", profile="study-code").fish_params()
    assert rules_of(orbit) == "homing"


def test_the_settings_digest_tells_decisions_apart_and_nothing_else(
    model: Path, tmp_path: Path
) -> None:
    from fishswarm.behaviors.registry import settings_digest
    from fishswarm.sim.decision_kernels import with_compiled_decisions
    from fishswarm.sim.scenario import Scenario

    def digest(**settings: object) -> str:
        return settings_digest(Scenario(**settings).fish_params())  # type: ignore[arg-type]

    formation = {"behavior": "formation", "fish": 8}
    assert len(digest(**formation)) == 16
    assert digest(**formation) == digest(**formation, seed=9, duration=5.0)  # not the fish's
    for changed in ({"fish": 15}, {"spacing": 0.25}, {"formation": "column"}, {"flags": False},
                    {"controller": "homing"}, {"profile": "study-code"}):  # fmt: skip
        assert digest(**formation) != digest(**{**formation, **changed}), changed
    # A large school's compiled Lennard-Jones loop decides as numpy does: one digest.
    large = Scenario(fish=500).fish_params()
    assert settings_digest(with_compiled_decisions(large, 500)) == settings_digest(large)
    # A replica's model is part of its decisions: another model's weights, another digest.
    other = tmp_path / "other.npz"
    np.savez(other, weights=np.zeros(21), settings='{"behavior": "aggregation"}')
    assert digest(behavior="replica", model=str(model)) == digest(
        behavior="replica", model=str(model)
    )
    assert digest(behavior="replica", model=str(model)) != digest(
        behavior="replica", model=str(other)
    )


def test_the_settings_parts_name_what_differs_and_nothing_else() -> None:
    """Each change of a fish-side setting shows in the part of its name alone; settings the
    fish do not read, and compiled loops, show in none."""
    from fishswarm.behaviors.core import FishParams
    from fishswarm.behaviors.registry import (
        PART_DIGEST_LENGTH,
        differing_parts,
        settings_digest,
        settings_parts,
    )
    from fishswarm.sim.decision_kernels import with_compiled_decisions
    from fishswarm.sim.scenario import Scenario

    def parts(**settings: object) -> dict[str, str]:
        return settings_parts(Scenario(**settings).fish_params())  # type: ignore[arg-type]

    formation = parts(behavior="formation", fish=8)
    assert list(formation)[:3] == ["shape", "count", "spacing"]
    assert list(formation)[-4:] == ["controller", "caudal_cap", "pid_gains", "right_when_ahead"]
    assert {len(part) for part in formation.values()} == {PART_DIGEST_LENGTH}
    assert differing_parts(formation, parts(behavior="formation", fish=8, seed=9)) == []
    for changed, names in (
        ({"fish": 15}, ["count"]),
        ({"spacing": 0.25}, ["spacing", "tolerance"]),  # a quarter of the spacing
        ({"formation": "column"}, ["shape"]),
        ({"flags": False}, ["flags"]),
        ({"controller": "homing"}, ["controller"]),
        ({"fish": 15, "flags": False}, ["count", "flags"]),
    ):
        other = parts(**{"behavior": "formation", "fish": 8, **changed})
        assert differing_parts(formation, other) == names, changed
    # Lennard-Jones: the study code's force form is a parameter of the behaviour, its homing
    # switch the fish's own.
    study = parts(profile="study-code")
    assert differing_parts(parts(), study) == ["study_form", "right_when_ahead"]
    large = Scenario(fish=500).fish_params()
    assert settings_parts(with_compiled_decisions(large, 500)) == settings_parts(large)
    # Equal parts, equal digest; and a part only one side has is named too.
    assert differing_parts({"a": "1"}, {"a": "1", "b": "2"}) == ["b"]
    assert differing_parts({"b": "2", "a": "1"}, {"a": "3"}) == ["b", "a"]
    # A behaviour's own settings, a table, by key; a parameter named as one of the fish's
    # own is told apart from it.
    behavior = Scenario().fish_params().behavior
    own = FishParams(behavior, {"distance": 0.3, "controller": "sway"})
    assert list(settings_parts(own))[:2] == ["distance", "steering.controller"]
    assert settings_parts(FishParams(behavior, 7.0)).keys() >= {"steering", "controller"}
    assert settings_digest(own) != settings_digest(FishParams(behavior, {"distance": 0.4}))


def test_a_fish_counts_the_effort_of_the_fins_it_commanded() -> None:
    from fishswarm.bluebot.parameters import effort_rate
    from fishswarm.protocols.messages import FormationFlag

    params = fish_params(
        {"behavior": "formation", "formation": "column", "fish": 2, "controller": "pid",
         "tank": TANK}
    )  # fmt: skip
    neighbors = np.array([[[0.8, 0.3, 0.1]]])

    def seen_at(time: float) -> Perception:
        return Perception(
            np.array([time]), np.array([0.5]), neighbors, np.ones((1, 1), dtype=np.bool_),
            np.zeros((1, 0, 3)), np.zeros((1, 0), dtype=np.bool_), np.zeros(1),
        )  # fmt: skip

    memory, first = decide(FishMemory.fresh(params, 1), seen_at(1.0), Inbox.empty(1),
                           params=params)  # fmt: skip
    assert memory.effort.tolist() == [0.0]  # nothing ran before the first decision
    np.testing.assert_array_equal(memory.fins, first.fins)
    memory, second = decide(memory, seen_at(1.5), Inbox.empty(1), params=params)
    # The first decision's fins ran for 0.5 s: gain times frequency, summed over fins.
    spent = float(effort_rate(first.fins)[0]) * 0.5
    assert spent > 1 and memory.effort.tolist() == [pytest.approx(spent, rel=1e-15)]
    assert FormationFlag.from_values(second.outbox.values[0]).effort == round(spent)


def test_a_second_pid_decision_at_the_same_time_counts_one_nominal_period() -> None:
    """Elapsed 0 (a repeated time, a clock that stood still) is no period to integrate
    over: the loops take the nominal 0.5 s, as at a first decision — the same fins as a
    decision exactly one period later."""
    params = fish_params(
        {"behavior": "aggregation", "controller": "pid", "tank": TANK, "control_period": 0.5}
    )
    ahead = Perception(
        np.array([2.0]), np.array([0.5]), np.array([[[1.0, 0.2, 0.1]]]), np.ones((1, 1), bool),
        np.zeros((1, 0, 3)), np.zeros((1, 0), bool),
    )  # fmt: skip
    first, _ = decide(FishMemory.fresh(params, 1), ahead, Inbox.empty(1), params=params)
    again, repeated = decide(first, ahead, Inbox.empty(1), params=params)
    later = dataclasses.replace(ahead, time=np.array([2.5]))
    _, on_time = decide(first, later, Inbox.empty(1), params=params)
    assert np.isfinite(repeated.fins).all()
    np.testing.assert_array_equal(repeated.fins, on_time.fins)
    assert again.pid.integral[0, 0] == pytest.approx(first.pid.previous_error[0, 0] * 1.0)


def test_a_fish_needs_a_positive_control_period() -> None:
    with pytest.raises(ValueError, match="control_period must be positive"):
        FishParams(behavior_named("orbit"), None, control_period=0.0)


def test_inbox_of_is_as_wide_as_the_fish_that_heard_most() -> None:
    heard = (1, np.array([4]), np.array([0.1, 0.2, 0.3]))
    inbox = inbox_of([[], [heard, heard]])
    assert inbox.mask.tolist() == [[False, False], [True, True]]


def test_a_replica_moves_as_far_as_its_period_lets_it(tmp_path: Path) -> None:
    # The replica of test_replica_motion_by_hand moves 9 units/s straight ahead: 0.0534 m in
    # a 1-s period, half that in 0.5 s; the fish's control period comes from the scenario.
    weights = np.zeros(21)
    weights[18:21] = [50.0, 0.0, 50.0]
    neighbors, mask = np.array([[[0.3, 0.1, 0.0]]]), np.ones((1, 1), bool)
    half = replica_motion(neighbors, mask, weights=weights, period=0.5)
    np.testing.assert_allclose(half, [[4.5 * STUDY_SCALE, 0.0]], atol=1e-15)
    path = tmp_path / "replica.npz"
    np.savez(path, weights=weights, settings=np.array('{"arena": {}}'))
    settings = {"behavior": "replica", "model": str(path), "tank": TANK, "control_period": 0.5}
    assert fish_params(settings).steering.period == 0.5


def _steering_of(target: np.ndarray, led: np.ndarray | None = None) -> Steering:
    count = target.shape[0] if target.ndim else 1
    return Steering(target, np.ones(count, bool) if led is None else led, Outbox.silent(count))


@pytest.mark.parametrize(
    ("steer", "said"),
    [
        (
            lambda m, p, i, *, params: (
                m,
                steady(p.neighbors[np.arange(p.count), np.argmin(p.neighbor_mask, axis=1)]),
            ),
            "its steer raised ValueError: attempt to get argmin of an empty sequence",
        ),
        (
            lambda m, p, i, *, params: _steering_of(np.zeros((p.count, 3))),
            "its steer must return (memory, Steering), got Steering",
        ),
        (
            lambda m, p, i, *, params: (m, _steering_of(np.zeros((p.count, 2)))),
            "its target must be (B, 3) = (3, 3) in m, got shape (3, 2)",
        ),
        (
            lambda m, p, i, *, params: (
                m,
                _steering_of(np.array([[1.0, 0, 0], [np.nan, 0, 0], [0, 0, np.inf]])),
            ),
            "its target is not finite for fish rows [1, 2]",
        ),
        (
            lambda m, p, i, *, params: (m, _steering_of(np.array([[0.3, None, 0.0]] * p.count))),
            "its target must hold numbers, got dtype object",
        ),
        (
            lambda m, p, i, *, params: (m, _steering_of(np.zeros((p.count, 3)), np.ones(1, bool))),
            "its led must have shape (3,), got (1,)",
        ),
    ],
)
def test_a_behaviour_that_errs_is_named_with_what_is_wrong(steer: Steer, said: str) -> None:
    # A behaviour of one's own that fails, or gives what no controller can use: said where
    # it happens, not as an IndexError in the controller or a message check after.
    family = Behavior("mine", "a test's", steer, no_memory, lambda settings: None, spawn_radius=0.5)
    params = FishParams(family, None)
    perception = Perception(
        np.zeros(3), np.full(3, 0.5), np.zeros((3, 0, 3)), np.zeros((3, 0), bool),
        np.zeros((3, 0, 3)), np.zeros((3, 0), bool),
    )  # fmt: skip
    with pytest.raises(BehaviorError) as error:
        decide(FishMemory.fresh(params, 3), perception, Inbox.empty(3), params=params)
    assert str(error.value) == (
        f"the behaviour 'mine' deciding for 3 fish (0 neighbour rows each): {said}"
    )
