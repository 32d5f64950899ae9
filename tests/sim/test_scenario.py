"""Scenario settings: defaults from the study, TOML loading, clear errors."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from fishswarm.sim.scenario import ConfigError, Scenario
from fishswarm.study.catalog import EXPERIMENTS_FOLDER
from tests.behaviors import example_plugin


def test_defaults_follow_the_study() -> None:
    dispersion = Scenario()
    assert (dispersion.fish, dispersion.duration, dispersion.control_period) == (25, 15.0, 1.0)
    assert dispersion.ticks == 15
    assert dispersion.resolved_target_distance() == pytest.approx(2.517, abs=1e-3)
    assert dispersion.resolved_spawn_radius() == pytest.approx(0.26)
    aggregation = Scenario(behavior="aggregation")
    assert aggregation.resolved_target_distance() == pytest.approx(0.26)
    assert aggregation.resolved_spawn_radius() == pytest.approx(1.3)


def test_the_controller_defaults_to_the_behaviours_and_a_named_one_stays() -> None:
    from fishswarm.behaviors.registry import fish_params

    assert Scenario().controller == "homing"
    assert Scenario(behavior="formation").controller == "pid"
    assert Scenario(behavior="formation", controller="homing").controller == "homing"
    assert Scenario(behavior="dispersion", controller="pid").controller == "pid"
    # What a recording holds reads back as what ran; settings without one get the default.
    formation = Scenario(behavior="formation")
    assert Scenario.from_mapping(formation.to_dict()).controller == "pid"
    assert fish_params({"behavior": "formation"}).controller == "pid"
    assert fish_params({"behavior": "orbit", "orbit_radius": 0.45}).controller == "homing"
    # Another behaviour given later (fishswarm run --behavior over the defaults or a file)
    # brings its own default, unless a controller was chosen.
    assert Scenario().replace(behavior="formation").controller == "pid"
    assert Scenario().replace(behavior="formation", controller="homing").controller == "homing"
    assert Scenario(controller="pid").replace(behavior="aggregation").controller == "pid"
    assert formation.replace(behavior="orbit").controller == "homing"


def test_run_behavior_formation_steers_with_pid_from_the_command_line(tmp_path: Path) -> None:
    from fishswarm.cli.parsers import build_parser, scenario_from

    parser = build_parser()
    chosen = scenario_from(parser.parse_args(["run", "--behavior", "formation"]))
    assert chosen.controller == "pid"
    named = scenario_from(parser.parse_args(["run", "--behavior", "formation", "--controller",
                                             "homing"]))  # fmt: skip
    assert named.controller == "homing"
    # A file that names the controller keeps it, also when it is the file's behaviour's
    # default; a file that does not name one lets the new behaviour bring its own.
    for text, controller in (('controller = "homing"', "homing"), ("fish = 4", "pid")):
        path = tmp_path / "s.toml"
        path.write_text(f'[scenario]\nbehavior = "dispersion"\n{text}\n')
        args = parser.parse_args(["run", "--config", str(path), "--behavior", "formation"])
        assert scenario_from(args).controller == controller


def test_toml_loads_and_rejects_unknown_keys(tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    path.write_text("[scenario]\nfish = 10\ntank = [3, 3, 1]\nblind_width = 0\n")
    scenario = Scenario.from_toml(path)
    assert scenario.fish == 10 and scenario.tank == (3.0, 3.0, 1.0)
    assert scenario.blind_width == 0.0
    path.write_text("fsh = 3\n")
    with pytest.raises(ConfigError, match=r"unknown setting\(s\) fsh; known settings are"):
        Scenario.from_toml(path)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"fish": 0}, "fish must be a whole number"),
        ({"controller": "ai"}, "controller must be one of homing, pid"),
        ({"tank": (1.0, -1.0, 1.0)}, "tank size must be three positive lengths"),
        ({"blind_width": -0.1}, "blind_width must be a finite non-negative number"),
        ({"channel_loss": 1.0}, "channel_loss must be a probability"),
        ({"swarm": "a b"}, "letters, digits"),
        ({"seed": -1}, r"seed must be a whole number from 0 to 2\*\*62"),
        # One past what a message's integer may be: the world tells its seed in one.
        (
            {"seed": 2**62 + 1},
            r"seed must be a whole number from 0 to 2\*\*62 \(4611686018427387904\)",
        ),
        ({"flow": (0.1, math.nan, 0.0)}, r"flow must be a velocity \(x, y, z\) in m/s"),
        ({"wake_saving": 1.0}, r"wake_saving must be a fraction in \[0, 1\)"),
        ({"wake_width": 0.0}, "wake_length and wake_width must be positive lengths"),
        ({"station_distance": 0.2}, r"station_distance needs a landmark to hold station behind"),
        (
            {"station_distance": -0.2, "landmark": (0.5, 0.5, 0.5)},
            "station_distance must be a length of 0 m or more, got -0.2",
        ),
        ({"slot_rule": "nearest"}, "slot_rule must be one of share, study, got 'nearest'"),
        ({"local_rule": "grid"}, "local_rule must be one of lattice, neighbors, got 'grid'"),
        ({"effort_margin": -1.0}, "effort_margin must be 0 or more"),
        ({"rotate_effort": "yes"}, "flags and rotate_effort must be true or false"),
        ({"formation_heading_deg": math.nan}, "formation_heading_deg must be a finite angle"),
        ({"spacing": math.inf}, "spacing must be positive metres"),
        ({"tolerance": 0.0}, "tolerance must be positive metres"),
        ({"caudal_cap": 1.5}, r"caudal_cap must be in \(0, 1\], got 1.5"),
        ({"formation_lead": 60.0}, r"formation_lead must be a time in \[0, 60\) s, got 60.0"),
        (
            {"switch_at": 15.5, "duration": 15.0},
            r"switch_at must be a time within the run, \[0, 15\] s \(its duration\), got 15.5",
        ),
        (
            {"behavior": "orbit", "orbit_radius": 0.89},
            r"orbit_radius \(0.89 m\) does not fit in the tank .*keep it below 0.89 m",
        ),
    ],
)
def test_bad_settings_say_what_is_wrong(changes: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        Scenario().replace(**changes)


def test_settings_at_the_edge_of_their_range_are_allowed() -> None:
    # The longest period, a run of one period, a full caudal fin, a switch at the very end.
    assert Scenario(duration=60.0, control_period=60.0).ticks == 1
    assert Scenario(duration=0.5, control_period=0.5).check_duration().ticks == 1
    assert Scenario(caudal_cap=1.0).caudal_cap == 1.0
    assert Scenario(duration=15.0, switch_at=15.0).switch_at == 15.0
    assert Scenario(formation_lead=0.0).formation_lead == 0.0
    # A period that divides the duration up to rounding (0.3 / 0.1 is 2.9999999999999996)
    # gives whole periods; half a millisecond over ten periods does not.
    assert Scenario(duration=0.3, control_period=0.1).check_duration().ticks == 3
    with pytest.raises(ConfigError, match=r"duration \(10.0005 s\) .* e.g. 10 or 11 s"):
        Scenario(duration=10.0005).check_duration()


@pytest.mark.parametrize(
    ("text", "named"),
    [
        ("fish = 5\n[scenario]\nfish = 7\n", "fish outside the [scenario] table"),
        ("[scenario]\nfish = 7\n[other]\nx = 1\n", "other outside the [scenario] table"),
    ],
)
def test_settings_a_scenario_file_would_ignore_are_refused(
    tmp_path: Path, text: str, named: str
) -> None:
    path = tmp_path / "s.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=re.escape(f"s.toml: {named} would be ignored")):
        Scenario.from_toml(path)


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("fish = true", "fish must be a whole number, got true$"),
        ("seed = 1.5", "seed must be a whole number, got 1.5"),
        (
            "tank = [1.78, 1.78, true]",
            r"tank must be a list of three numbers \(m\), got \[1.78, 1.78, true\]$",
        ),
        ('flow = ["a", 0, 0]', r"flow must be a list of three numbers \(m/s\)"),
        (
            "flow = [0.1, 0]",
            r"flow must be a list of three speeds \(x, y, z, m/s\), got \[0.1, 0\]$",
        ),
        ("tank = [2, 2]", r"tank must be a list of three lengths \(x, y, z, m\), got \[2, 2\]$"),
        ('wake_saving = "0.3"', r'wake_saving must be a finite number, got "0.3"$'),
        ("sphere_radius = nan", "sphere_radius must be a finite number, got nan"),
        ("formation_heading_deg = inf", "formation_heading_deg must be a finite number"),
        ("swarm = 3", r"swarm must be text \(in quotes\), got 3"),
        ("model = 3", r"model must be text \(in quotes\), got 3"),
        ('flags = "yes"', r'flags must be true or false, got "yes"$'),
    ],
)
def test_a_file_setting_of_the_wrong_kind_is_named(tmp_path: Path, line: str, message: str) -> None:
    path = tmp_path / "s.toml"
    path.write_text(f"[scenario]\n{line}\n")
    with pytest.raises(ConfigError, match=f"s.toml: {message}"):
        Scenario.from_toml(path)
    # A run must last a whole number of periods (where one starts: run, world, experiments;
    # a robot's fish never uses the duration, and a recording says what already ran).
    with pytest.raises(
        ConfigError,
        match=r"duration \(2.5 s\) must be a whole number of control periods \(1 s\): "
        r"e.g. 2 or 3 s",
    ):
        Scenario(duration=2.5).check_duration()
    assert Scenario.as_recorded(Scenario(duration=2.5).to_dict()).duration == 2.5
    # Durations and periods that are whole numbers and periods that divide them are fine.
    path.write_text("[scenario]\nduration = 3\ncontrol_period = 0.1\nseed = 2\n")
    assert Scenario.from_toml(path).check_duration().ticks == 30


SHIPPED = sorted(EXPERIMENTS_FOLDER.glob("*.toml"))


@pytest.mark.parametrize(
    "path", [p for p in SHIPPED if "[experiment]" not in p.read_text(encoding="utf-8")]
)
def test_shipped_scenario_files_load(path: Path) -> None:
    scenario = Scenario.from_toml(path)
    assert scenario.behavior == path.stem


def test_settings_are_checked_together_and_name_what_the_user_set() -> None:
    # A short period no longer trips over the default jitter, which only jitter mode uses.
    assert Scenario(control_period=0.01).ticks == 1500
    with pytest.raises(
        ConfigError, match=r"jitter \(0.05 s\) must not exceed the control period \(0.01 s\)"
    ):
        Scenario(control_period=0.01, time_mode="jitter")
    with pytest.raises(
        ConfigError, match=r"duration \(10 s\) is shorter than one control period \(50 s\)"
    ):
        Scenario(duration=10.0, control_period=50.0)
    with pytest.raises(ConfigError, match=r"control_period must be at most 60 s"):
        Scenario(duration=200.0, control_period=100.0)
    with pytest.raises(ConfigError, match=r"target_distance must be at most 1000 m"):
        Scenario(target_distance=1e100)
    with pytest.raises(
        ConfigError,
        match=r"orbit_radius \(5 m\) does not fit in the tank \(1.78 × 1.78 m\): keep it below",
    ):
        Scenario(behavior="orbit", orbit_radius=5.0)
    assert Scenario(behavior="waltz", orbit_radius=1.0).orbit_radius == 1.0  # a partner distance
    with pytest.raises(ConfigError, match=r"orbit_radius \(2 m\) does not fit.*below 1.78 m"):
        Scenario(behavior="waltz", orbit_radius=2.0)  # partners 2 m apart: no room
    # Formation flags are not delivered in jitter mode: refused unless turned off.
    with pytest.raises(ConfigError, match="formation flags are not delivered in jitter mode"):
        Scenario(behavior="formation", time_mode="jitter")
    assert not Scenario(behavior="formation", time_mode="jitter", flags=False).flags
    assert Scenario(behavior="dispersion", time_mode="jitter").flags  # flags only matter there
    # A recording of such a run, made before they were refused, reads as it ran: no flags.
    recorded = Scenario(behavior="formation").to_dict() | {"time_mode": "jitter"}
    with pytest.raises(ConfigError, match="not delivered in jitter mode"):
        Scenario.from_mapping(recorded)
    ran = Scenario.as_recorded(recorded)
    assert (ran.behavior, ran.time_mode, ran.flags) == ("formation", "jitter", False)


@pytest.mark.parametrize(
    "scenario",
    [
        Scenario(),
        Scenario(behavior="milling", orbit_radius=0.3, fish=3),
        Scenario(behavior="aggregation", landmark=(0.5, 0.5, 0.5), tank=(2.0, 2.0, 1.0)),
        Scenario(behavior="formation", formation="pyramid", switch_formation="diamond"),
    ],
)
def test_settings_read_back_from_a_recording_give_the_same_scenario(scenario: Scenario) -> None:
    # to_dict writes None for what is not set (a landmark, a formation): read back as unset.
    again = Scenario.from_mapping(scenario.to_dict(), source="recording")
    assert again.to_dict() == scenario.to_dict()
    np.testing.assert_array_equal(again.landmarks(), scenario.landmarks())


def test_study_code_switches_change_only_what_they_name(tmp_path: Path) -> None:
    from fishswarm.sim.engine import simulate_batch

    assert Scenario().robot() == Scenario(study_code=()).robot()
    euler = Scenario(study_code=("euler-step",)).robot()
    assert (euler.euler_step, euler.yaw_before_update, euler.speed_dependent_drag) == (
        0.1,
        True,
        False,
    )
    assert Scenario(study_code=("drag",)).robot().speed_dependent_drag
    path = tmp_path / "s.toml"
    path.write_text('[scenario]\nfish = 4\nduration = 4\nstudy_code = ["drag", "euler-step"]\n')
    loaded = Scenario.from_toml(path)
    assert loaded.study_code == ("drag", "euler-step")
    again = Scenario.from_mapping(loaded.to_dict())
    assert again.study_code == loaded.study_code
    # Deterministic, and not the paper's trajectory.
    first, second = simulate_batch(loaded), simulate_batch(loaded)
    np.testing.assert_array_equal(first.position, second.position)
    paper = simulate_batch(loaded.replace(study_code=()))
    assert np.abs(first.position[-1] - paper.position[-1]).max() > 1e-3


@pytest.mark.parametrize(
    ("given", "message"),
    [
        ('study_code = ["wobble"]', "unknown switch(es) 'wobble'; the switches are euler-step"),
        ('study_code = "drag"', 'study_code must be a list of switch names, e.g. ["drag"]'),
    ],
)
def test_bad_study_code_switches_are_named(tmp_path: Path, given: str, message: str) -> None:
    path = tmp_path / "s.toml"
    path.write_text(f"[scenario]\n{given}\n")
    with pytest.raises(ConfigError, match=re.escape(message)):
        Scenario.from_toml(path)


def test_the_study_code_profile_sets_every_switch_and_each_reaches_its_place() -> None:
    from fishswarm.sim.physics import WorldParams
    from fishswarm.sim.scenario import STUDY_CODE_SWITCHES

    paper, study = Scenario(), Scenario(profile="study-code")
    assert paper.study_switches == ()
    assert study.study_switches == tuple(STUDY_CODE_SWITCHES)
    assert Scenario(study_code=("homing",)).study_switches == ("homing",)
    # Fish side: the Lennard-Jones form and the homing branch.
    assert not paper.fish_params().right_when_ahead
    assert not paper.fish_params().steering.study_form
    assert study.fish_params().right_when_ahead
    assert study.fish_params().steering.study_form
    assert Scenario(study_code=("lennard-jones",)).fish_params().steering.study_form
    assert not Scenario(study_code=("lennard-jones",)).fish_params().right_when_ahead
    # World side: dynamics, links, start delay.
    assert (paper.vision().manhattan, study.vision().manhattan) == (False, True)
    assert WorldParams.of(paper).still_until == 0.0
    assert WorldParams.of(study.replace(control_period=0.5)).still_until == 1.0
    assert study.robot().euler_step == 0.1
    # The profile reads back from a recording's settings.
    assert Scenario.from_mapping(study.to_dict()).profile == "study-code"


def test_bad_profiles_and_manhattan_with_cameras_are_refused() -> None:
    with pytest.raises(ConfigError, match="profile must be one of paper, study-code, got 'code'"):
        Scenario(profile="code")
    with pytest.raises(ConfigError, match="Manhattan links change the geometric vision model"):
        Scenario(profile="study-code", vision_model="camera")
    assert Scenario(study_code=("drag", "homing"), vision_model="camera").vision_model == "camera"


def test_a_lone_fish_circles_under_the_study_codes_homing() -> None:
    from fishswarm.sim.engine import simulate_batch

    # Alone it sees nobody: the target is zero, bearing 0. The paper's controller runs only
    # the caudal fin (0.1) and the fish swims straight; the study's code drives the right
    # pectoral at 0.6 too, which turns the fish to its own left (z down) — clockwise in a
    # plan view with y up, how the study and fishswarm draw the tank ("circles right").
    paper = simulate_batch(Scenario(fish=1, duration=60))
    study = simulate_batch(Scenario(fish=1, duration=60, study_code=("homing",)))
    np.testing.assert_array_equal(paper.yaw, np.full_like(paper.yaw, paper.yaw[0]))
    yaw = np.unwrap(study.yaw[:, 0])
    assert np.all(np.diff(yaw)[1:] < 0)  # turning the same way all along
    assert (yaw[0] - yaw[-1]) / (2 * np.pi) > 1.5  # more than one and a half turns
    planar = study.position[:, 0, :2]
    assert np.ptp(planar, axis=0).max() < 0.3  # a small circle, not a wall-to-wall path
    # The path goes round the same way: clockwise with y up, its signed (shoelace) area
    # negative, and the bearing of the fish from the circle's centre falls.
    x, y = planar[:, 0], planar[:, 1]
    assert 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) < -0.01
    around = planar[10:] - planar[10:].mean(axis=0)
    bearing = np.unwrap(np.arctan2(around[:, 1], around[:, 0]))
    assert bearing[-1] - bearing[0] < -2 * np.pi


def test_a_robots_fish_takes_any_period_and_run_checks_its_duration() -> None:
    from fishswarm.cli.parsers import build_parser, scenario_from

    parser = build_parser()
    fish = parser.parse_args(["fish", "--id", "0", "--period", "0.4"])
    assert scenario_from(fish).control_period == 0.4  # no duration of its own to divide
    with pytest.raises(ConfigError, match="whole number of control periods"):
        scenario_from(parser.parse_args(["run", "--period", "0.4"]))


def test_vision_settings_apply_to_a_camera_run_only_where_the_geometric_model_serves_it() -> None:
    from fishswarm.sim.scenario import unmet_condition

    camera = Scenario(vision_model="camera", fish=3)
    assert unmet_condition("blind_width", camera) == ("vision_model", "geometric")
    assert unmet_condition("blind_width", Scenario()) is None
    # A landmark is seen by the geometric model (an orbit's post too), and so are formation
    # flags by light: there the settings mean something even with cameras.
    assert unmet_condition("sphere_radius", camera.replace(landmark=(1.0, 1.0, 0.5))) is None
    assert unmet_condition("visual_range", camera.replace(behavior="orbit", fish=1)) is None
    lit = camera.replace(behavior="formation", flag_medium="light")
    assert unmet_condition("vision_noise", lit) is None
    assert unmet_condition("vision_noise", lit.replace(flag_medium="beacon")) == (
        "vision_model",
        "geometric",
    )


def test_a_files_setting_refused_alone_is_checked_again_with_the_flags_that_mend_it(
    tmp_path: Path,
) -> None:
    from fishswarm.cli.parsers import build_parser, scenario_from

    config = tmp_path / "late.toml"
    config.write_text(
        'behavior = "formation"\nduration = 30\nswitch_formation = "diamond"\nswitch_at = 82.5\n'
    )
    parser = build_parser()
    mended = scenario_from(parser.parse_args(["run", "--config", str(config), "--duration", "100"]))
    assert (mended.duration, mended.switch_at) == (100.0, 82.5)
    # Not mended: the message names the file and the duration it checked against.
    for words, duration in (([], 30), (["--duration", "50"], 50)):
        with pytest.raises(ConfigError, match=rf"late.toml: switch_at .*\[0, {duration}\] s"):
            scenario_from(parser.parse_args(["run", "--config", str(config), *words]))


def test_a_model_that_names_a_learning_runs_folder_points_at_the_file_in_it(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"is a folder, not a learned replica file \('fishswarm"):
        Scenario(behavior="replica", model=str(tmp_path))
    (tmp_path / "best_replica.npz").write_bytes(b"")
    with pytest.raises(ConfigError, match=rf"give {tmp_path / 'best_replica.npz'}$"):
        Scenario(behavior="replica", model=str(tmp_path))


def test_a_behaviours_own_settings_are_checked_kept_in_name_order_and_read_back(
    tmp_path: Path,
) -> None:
    example_plugin.registered()  # nearest: distance 0.26, cruise 0.52 by default
    scenario = Scenario(behavior="nearest", behavior_settings=(("distance", 1), ("cruise", 0.4)))
    assert scenario.behavior_settings == (("cruise", 0.4), ("distance", 1.0))
    assert isinstance(scenario.behavior_settings[1][1], float)  # a whole number, as a number
    assert scenario.to_dict()["behavior_settings"] == {"cruise": 0.4, "distance": 1.0}
    read_back = Scenario.from_mapping(scenario.to_dict())  # defaults resolved, as recorded
    assert read_back.behavior_settings == scenario.behavior_settings
    # None given: left out of what a recording or summary holds, as before there were any.
    assert "behavior_settings" not in Scenario(behavior="nearest").to_dict()
    path = tmp_path / "s.toml"
    path.write_text('[scenario]\nbehavior = "nearest"\n[scenario.behavior_settings]\ncruise = 1\n')
    assert Scenario.from_toml(path).behavior_settings == (("cruise", 1.0),)
    refused = {
        "distance = 0.3\n": (
            "s.toml: behavior_settings: dispersion has no setting 'distance'; it has no "
            "settings of its own"
        ),
    }
    for table, message in refused.items():
        path.write_text(f"[scenario.behavior_settings]\n{table}")
        with pytest.raises(ConfigError, match=f"{re.escape(message)}$"):
            Scenario.from_toml(path)
    path.write_text('[scenario]\nbehavior = "nearest"\nbehavior_settings = 3\n')
    with pytest.raises(
        ConfigError,
        match=re.escape(
            "s.toml: behavior_settings must be a table of NAME = VALUE, e.g. { gain = 0.5 }, got 3"
        ),
    ):
        Scenario.from_toml(path)
    wrong = {
        "gap": "behavior_settings: nearest has no setting 'gap'; its settings are distance, cruise",
        "distance": (
            "behavior_settings: distance of nearest must be a finite number (its default is "
            '0.26), got "far"'
        ),
    }
    for name, message in wrong.items():
        with pytest.raises(ConfigError, match=f"^{re.escape(message)}$"):
            Scenario(behavior="nearest", behavior_settings=((name, "far"),))
    with pytest.raises(ConfigError, match=r"must be a finite number .*, got true$"):
        Scenario(behavior="nearest", behavior_settings=(("distance", True),))


def test_a_behaviour_is_named_with_the_own_settings_a_run_gave_it() -> None:
    from fishswarm.sim.scenario import behavior_text

    assert behavior_text("nearest", (("cruise", 0.5), ("distance", 0.3))) == (
        "nearest (cruise 0.5, distance 0.3)"
    )
    assert behavior_text("mine", {"fast": True, "mode": "pairs"}) == "mine (fast true, mode pairs)"
    assert behavior_text("dispersion") == "dispersion"
    assert behavior_text(None, None) == "?"  # a recording that does not say


def test_a_behaviours_text_setting_longer_than_a_message_carries_is_refused() -> None:
    import dataclasses

    from fishswarm.behaviors.registry import BEHAVIORS, register
    from tests.behaviors.signal_behavior import SIGNAL

    labelled = dataclasses.replace(SIGNAL, name="test-labelled", settings={"label": "a"})
    if labelled.name not in BEHAVIORS:
        register(labelled)
    assert Scenario(behavior="test-labelled", behavior_settings=(("label", "b" * 4096),))
    with pytest.raises(ConfigError, match="label of test-labelled must be at most 4096 characters"):
        Scenario(behavior="test-labelled", behavior_settings=(("label", "b" * 4097),))
