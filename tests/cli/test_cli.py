"""The fishswarm command as a user runs it: real processes, real files, real exit codes."""

from __future__ import annotations

import json
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fishswarm.sim.engine import simulate_batch
from fishswarm.sim.scenario import ConfigError, Scenario
from fishswarm.study.recording import read_recording
from tests.conftest import free_port, wait_for_port

pytestmark = pytest.mark.integration

FISHSWARM = [sys.executable, "-m", "fishswarm"]


def _run(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*FISHSWARM, *args], capture_output=True, text=True, timeout=timeout, check=False
    )


def _outputs(tmp_path: Path, summary: Path) -> list[str]:
    """Arguments that give a run a free port, a recording in tmp_path and ``summary``."""
    listen = f"tcp/127.0.0.1:{free_port()}"
    return ["--listen", listen, "--record", str(tmp_path / "r.mcap"), "--summary", str(summary)]


@pytest.mark.slow
def test_run_writes_recording_and_summary_then_export_reads_it(tmp_path: Path) -> None:
    record, summary = tmp_path / "run.mcap", tmp_path / "run.json"
    result = _run(
        "run",
        "--fish",
        "6",
        "--duration",
        "4",
        "--seed",
        "7",
        "--procs",
        "2",
        "--listen",
        f"tcp/127.0.0.1:{free_port()}",
        "--record",
        str(record),
        "--summary",
        str(summary),
    )
    assert result.returncode == 0, result.stderr
    assert "tick 4/4" in result.stderr
    data = json.loads(summary.read_text())
    assert data["status"] == "finished"
    assert data["scenario"]["fish"] == 6 and data["scenario"]["seed"] == 7
    assert data["counts"]["ticks"] == 4
    assert data["real_time_factor"] > 1
    # The console's times agree with the summary's: the factor is of the ticks' time.
    said = re.search(r"wall ([\d.]+) s \(ticks ([\d.]+) s of it: (\d+)× real time\)", result.stderr)
    assert said is not None, result.stderr
    assert float(said[1]) == pytest.approx(data["wall_time"], abs=0.006)
    assert float(said[2]) == pytest.approx(data["loop_time"], abs=0.006)
    # Where the run went: the recording and this summary, named.
    assert f"  recording: {record}\n  summary: {summary}" in result.stderr
    assert data["summary"] == str(summary)
    assert int(said[3]) == round(data["real_time_factor"])
    # Where a tick went: each part of the world's a share of the loop, the fish's answer too.
    parts = data["world_time"]
    assert set(parts) == {"physics", "vision", "perceptions"}
    per_tick = data["loop_time"] / data["counts"]["ticks"]
    assert all(0 < seconds < per_tick for seconds in parts.values())
    assert 0 < data["answer_time"]["median"] < per_tick
    assert "the world's steps (medians): physics " in result.stderr
    for name in (
        "centroid_distance",
        "pairwise_distance",
        "nearest_neighbor_distance",
        "neighbors_seen",
    ):
        assert set(data["metrics"][name]) == {"initial", "final", "change_percent"}

    npz, csv = tmp_path / "out.npz", tmp_path / "out.csv"
    exported = _run("export", str(record), "--npz", str(npz), "--csv", str(csv))
    assert exported.returncode == 0, exported.stderr
    arrays = np.load(npz)
    assert arrays["t"].tolist() == [0.0, 1.0, 2.0, 3.0, 4.0]
    assert arrays["pos"].shape == (5, 6, 3)
    assert arrays["vel"].shape == (5, 6, 3)
    assert arrays["yaw"].shape == (5, 6)
    assert arrays["ids"].tolist() == [0, 1, 2, 3, 4, 5]
    rows = csv.read_text().splitlines()
    assert rows[0].startswith("tick,t,id,x,y,z")
    assert len(rows) == 1 + 5 * 6

    picture = tmp_path / "run.png"
    plotted = _run("plot", str(record), "--out", str(picture))
    assert plotted.returncode == 0, plotted.stderr
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    wrong = _run("plot", str(record), "--out", str(tmp_path / "run.gif"))
    assert wrong.returncode == 2
    assert "--out must end in .png, .svg or .pdf" in wrong.stderr

    gif, mp4 = tmp_path / "run.gif", tmp_path / "run.mp4"
    animated = _run("animate", str(record), "--out", str(gif), "--fish", "2", "--speed", "4")
    assert animated.returncode == 0, animated.stderr
    assert gif.read_bytes()[:6] == b"GIF89a"
    # 4 s of run at 4× and 10 fps: a frame every 0.4 s of the run, 11 in all.
    assert "(11 frames)" in animated.stderr
    movie = _run("animate", str(record), "--out", str(mp4), "--fps", "4", "--speed", "4")
    assert movie.returncode == 0, movie.stderr
    assert mp4.read_bytes()[4:8] == b"ftyp"
    stranger = _run("animate", str(record), "--out", str(gif), "--fish", "99")
    assert stranger.returncode == 2
    assert "fish 99 is not in the recording (fish: 0, 1, 2, 3, 4, 5)" in stranger.stderr
    # 4 s at 1e-4 of real time, 10 fps: 400 000 frames, far beyond what is worth making.
    slow = _run("animate", str(record), "--out", str(gif), "--speed", "1e-4")
    assert slow.returncode == 2
    assert "makes 400000 frames of this 4-s run, more than 20000: give --speed 0.002 or more" in (
        slow.stderr
    )


def test_toml_scenario_with_cli_override(tmp_path: Path) -> None:
    config = tmp_path / "scenario.toml"
    config.write_text('[scenario]\nfish = 4\nbehavior = "aggregation"\nduration = 2\nseed = 9\n')
    summary = tmp_path / "s.json"
    result = _run(
        "run",
        "--config",
        str(config),
        "--seed",
        "10",
        "--quiet",
        *_outputs(tmp_path, summary),
    )
    assert result.returncode == 0, result.stderr
    scenario = json.loads(summary.read_text())["scenario"]
    assert (scenario["fish"], scenario["behavior"], scenario["seed"]) == (4, "aggregation", 10)
    assert scenario["target_distance"] == pytest.approx(0.26)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["run", "--fish", "0"], "fish must be a whole number from 1 to 100000"),
        (["run", "--period", "0"], "--period: control_period must be a positive number"),
        (["fish", "--id", "0", "--id", "0"], "--id 0 given more than once: give each fish once"),
        (
            ["run", "--behavior", "formation", "--fish", "10001"],
            "a formation is for at most 10000 fish (its map's places), got 10001: give --fish "
            "10000 or fewer",
        ),
        (["run", "--behavior", "schooling"], "behavior must be one of dispersion, aggregation"),
        (["run", "--duration", "-3"], "duration must be a positive number of seconds"),
        (["run", "--listen", "localhost"], "write PROTOCOL/HOST:PORT"),
        (["run", "--procs", "-1"], "--procs must be 0 (the fish in this process) or more"),
        (["run", "--perception-timeout", "0"], "--perception-timeout must be a positive number"),
        (
            ["run", "--formation", "diamond"],
            "--formation applies only with --behavior formation, and this --behavior is "
            "dispersion: add --behavior formation, or leave --formation out",
        ),
        (["fish", "--id", "1", "--no-flags"], "--no-flags applies only with --behavior formation"),
        (["run", "--jitter", "0.1"], "--jitter applies only with --time jitter, and this --time"),
        (["run", "--spawn", "tank", "--spawn-radius", "1"], "--spawn-radius applies only with"),
        (["run", "--behavior", "waltz", "--model", __file__], "--model applies only with --beh"),
        (["world", "--orbit-radius", "0.3"], "--orbit-radius applies only with --behavior orbit"),
        (
            ["run", "--behavior", "formation", "--no-flags", "--flag-medium", "light"],
            "--flag-medium applies only without --no-flags: leave one of them out",
        ),
        (
            ["run", "--vision", "camera", "--blind-width", "0.5"],
            "--blind-width applies only with --vision geometric, and this --vision is camera: "
            "add --vision geometric, or leave --blind-width out; with cameras, vision settings "
            "still count where a landmark or formation flags by light are seen",
        ),
        (
            ["run", "--behavior", "formation", "--rotate-effort", "--no-flags"],
            "--rotate-effort applies only without --no-flags: leave one of them out",
        ),
        (
            ["run", "--behavior", "formation", "--rotate-effort", "--flag-medium", "beacon"],
            "--rotate-effort applies only with --flag-medium channel, and this --flag-medium is "
            "beacon: add --flag-medium channel, or leave --rotate-effort out",
        ),
        (["learn", "--resume", "--force"], "--resume continues the learning run in --out and"),
        (["learn", "--generations", "0"], "--generations must be at least 1, got 0"),
        (["learn", "--checkpoint-every", "0"], "--checkpoint-every must be at least 1, got 0"),
        (
            ["learn", "--radii", "unbounded"],
            "--radii unbounded says how learned radii move, but the inputs speed,counts learn none",
        ),
        (
            ["run", "--host", "lab", "--grpc-port", "9999"],
            "--host, --grpc-port apply only with --view: add --view, or leave them out",
        ),
        (
            ["view", "runs/any.mcap", "--connect", "tcp/127.0.0.1:7447", "--swarm", "other"],
            "--connect, --swarm apply only when following a live swarm (no RECORDING): a "
            "recording is replayed as it was recorded; leave them out",
        ),
        (
            ["observe", "--name", "laptop"],
            "--name applies only with --secure (it picks an observer certificate of a secured "
            "swarm): add --secure DIR, or leave it out",
        ),
        (
            ["run", "--fish", "2", "--log-level", "INFO"],
            "--log-level is an option of fishswarm itself: give it before the command, e.g. "
            "fishswarm --log-level INFO run",
        ),
        (["run", "--bogus"], "fishswarm run: error: unrecognized arguments: --bogus\n"),
        (
            ["secure", "init", "lab-keys", "--robts", "3"],
            "fishswarm secure init: error: unrecognized arguments: --robts 3 (did you mean "
            "--robots?)",
        ),
        (
            # Not read as the abbreviation of --seeds: it replaced a study's five-seed table.
            ["experiment", "blindspot", "--seed", "1"],
            "fishswarm experiment: error: unrecognized arguments: --seed 1 (did you mean --seeds?)",
        ),
        (["learn", "--generation", "3"], "unrecognized arguments: --generation 3 (did you mean"),
        (
            ["run", "--behaviour", "aggregation"],
            "fishswarm run: error: unrecognized arguments: --behaviour aggregation (did you "
            "mean --behavior?)",
        ),
        (["run", "--fish", "many"], "invalid int value"),
        (["export", "nowhere.mcap"], "say what to write"),
        (["run", "--vision", "sonar"], "vision_model must be one of geometric, camera"),
        (["run", "--spawn", "pool"], "spawn_region must be one of ball, tank, got 'pool'"),
        (["run", "--spawn-radius", "0"], "spawn_radius must be positive metres"),
        (["run", "--profile", "code"], "profile must be one of paper, study-code, got 'code'"),
        (["fish", "--id", "1", "--study-code", "drag,wobble"], "unknown switch(es) 'wobble'"),
        (["experiment", "blindspot", "--profile", "code"], "invalid choice: 'code'"),
        (
            ["robot", "--id", "1", "--period", "0.5", "--command-timeout", "0.4"],
            "command_timeout (0.4 s) must exceed the control period (0.5 s)",
        ),
        (["robot", "--id", "1", "--hardware", "lego"], "invalid choice: 'lego'"),
        (["robots", "--stop", "1", "--resume", "2"], "not allowed with argument"),
        (["run", "--start-timeout", "-1"], "'-1' is negative: give seconds, 0 or more"),
        (["world", "--start-timeout", "nan"], "'nan' is not a finite number of seconds"),
        (["observe", "--connect-timeout", "nan"], "'nan' is not a finite number of seconds"),
        (["fish", "--id", "-5"], "'-5' is negative: fish ids are 0 or more"),
        (["robot", "--id", "-1"], "'-1' is negative: fish ids are 0 or more"),
        (["robot", "--id", "1", "--link-timeout", "inf"], "'inf' is not a finite number"),
        (["robots", "--stop", "2", "x"], "'x' is not a whole number"),
        (["learn", "--soft-weight", "inf"], "soft_weight must be a finite number"),
        (
            ["robot", "--id", "1", "--perception-timeout", "0"],
            "perception_timeout must be a positive",
        ),
        (["learn", "--out", __file__], "is a file: give a folder to write into"),
        (["experiment", "blindspot", "--out", __file__], "is a file: give a folder"),
        (["run", "--record", "/proc/x.mcap"], "--record /proc/x.mcap: its folder /proc: cannot"),
        (
            ["world", "--record", f"{__file__}/x.mcap"],
            f"--record {__file__}/x.mcap: its folder {__file__} is a file: give a folder",
        ),
        (["fish", "--id", "1", "--connect", "bogus"], "--connect: endpoint 'bogus'"),
        (
            ["observe", "--connect", "tls/127.0.0.1:7447"],
            "is a secured (tls/) endpoint: give --secure DIR",
        ),
        (["run", "--listen", "tcp/127.0.0.1:0"], "with a port from 1 to 65535"),
        (["robots", "--swarm", "a/b"], "swarm name 'a/b' is not valid"),
        (["fish", "--id", "1", "--perception-timeout", "0"], "perception_timeout must be a"),
        (["observe", "--secure", "/nonexistent"], "/nonexistent is not a folder: give the one"),
        (["robot", "--id", "1", "--zenoh-config", "/nonexistent.json5"], "does not exist"),
        (["animate", "x.mcap", "--out", "x.gif", "--speed", "inf"], "a positive finite number"),
        (["observe", "--name", ""], "observer name '' is not valid"),
        (["fish", "--id", "9" * 23], "is too large: fish ids go up to"),
        (["observe", "--ticks", "-1"], "'-1' is negative: ticks count from 0"),
        (
            ["run", "--record", "runs/same", "--summary", "runs/same"],
            "--summary runs/same names the same file as --record: give --summary another file",
        ),
        (
            ["export", "x.mcap", "--csv", "x.mcap"],
            "--csv x.mcap names the same file as the recording, which this command reads",
        ),
        (["export", "x.mcap", "--npz", "o.npz", "--csv", "o.npz"], "the same file as --npz"),
        (["plot", "x.png", "--out", "x.png"], "names the same file as the recording"),
        (["run", "--listen", "tls/127.0.0.1:7447"], "is a secured (tls/) endpoint: give --secure"),
        (["run", "--period", "100", "--duration", "200"], "control_period must be at most 60 s"),
        (["world", "--connect", "bogus"], "--connect: endpoint 'bogus'"),
        (
            ["robots", "--listen", "tcp/127.0.0.1:7447"],
            "here --listen is how long to listen, s: give the router with --connect "
            "tcp/127.0.0.1:7447",
        ),
        (["run", "--config", str(Path(__file__).parent)], "is a folder, not a scenario file"),
        (
            ["run", "--config", str(Path(__file__).parents[2] / "experiments" / "orbit.toml")],
            "is an experiment (it has an [experiment] table), not a scenario: run it with "
            "'fishswarm experiment",
        ),
    ],
)
def test_bad_arguments_exit_nonzero_with_a_reason(args: list[str], message: str) -> None:
    result = _run(*args, timeout=30)
    assert result.returncode == 2
    assert message in result.stderr


def test_a_router_alone_listens_on_this_machine_only_unless_told_otherwise() -> None:
    from fishswarm.cli.parsers import build_parser

    parser = build_parser()
    assert parser.parse_args(["router"]).listen == "tcp/127.0.0.1:7447"
    assert parser.parse_args(["router", "--listen", "tcp/0.0.0.0:7447"]).listen.startswith(
        "tcp/0.0.0.0"
    )


def test_a_secured_command_listens_and_connects_over_tls_by_default(tmp_path: Path) -> None:
    """With --secure and no endpoint given, a command takes this machine's over TLS (a
    secured run complained of a --listen tcp/… its user never typed, and did not start);
    without --secure, over TCP; an endpoint given is kept."""
    from fishswarm.actors.security import init_secure
    from fishswarm.cli.parsers import build_parser

    folder = tmp_path / "keys"
    init_secure(folder)
    parser = build_parser()
    secured = ["--secure", str(folder)]
    assert parser.parse_args(["run", *secured]).listen == "tls/127.0.0.1:7447"
    assert parser.parse_args(["router", *secured]).listen == "tls/127.0.0.1:7447"
    assert parser.parse_args(["observe", *secured]).connect == "tls/127.0.0.1:7447"
    assert parser.parse_args(["observe"]).connect == "tcp/127.0.0.1:7447"
    given = parser.parse_args(["world", "--connect", "tls/10.0.0.1:7447", *secured])
    assert given.connect == "tls/10.0.0.1:7447"
    robots = parser.parse_args(["robots", *secured])
    assert (robots.connect, robots.listen) == ("tls/127.0.0.1:7447", 1.5)  # s, not a place


@pytest.mark.slow
def test_an_observer_with_no_world_to_watch_says_what_it_waits_for() -> None:
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    router = subprocess.Popen([*FISHSWARM, "router", "--listen", endpoint],
                              stderr=subprocess.DEVNULL)  # fmt: skip
    observer = None
    try:
        wait_for_port(port)
        observer = subprocess.Popen(
            [*FISHSWARM, "observe", "--connect", endpoint, "--swarm", "tank2"],
            stderr=subprocess.PIPE,
            text=True,
        )
        assert observer.stderr is not None
        lines = [observer.stderr.readline() for _ in range(2)]
        assert "observing swarm 'tank2'" in lines[0]
        assert "no snapshot of swarm 'tank2' after 10 s: waiting for its world" in lines[1]
        observer.send_signal(signal.SIGINT)
        assert observer.wait(timeout=15) == 130
    finally:
        for process in (observer, router):
            if process is not None and process.poll() is None:
                process.kill()
            if process is not None:
                process.communicate()


def test_fish_piled_on_one_another_at_the_start_are_warned_of_with_the_way_out() -> None:
    from fishswarm.cli.swarm import start_warnings

    assert start_warnings(Scenario()) == []  # the study's 25 fish, 6 cm apart
    assert start_warnings(Scenario(fish=1000, spawn_region="tank")) == []  # 8.5 cm
    (warning,) = start_warnings(Scenario(fish=1000))  # the study's ball: 2.3 cm
    assert warning.startswith("the 1000 fish start a median 2.3 cm from their nearest")
    assert "the study's dispersion start puts 25 fish 6 cm apart" in warning
    assert "--spawn tank" in warning and "--spawn-radius" in warning
    # Already spread over the whole tank: only a larger tank helps.
    (packed,) = start_warnings(Scenario(fish=20_000, spawn_region="tank"))
    assert packed.endswith("a larger tank (tank = [x, y, z] in a --config file)")


def test_a_start_ball_past_the_tanks_walls_is_warned_of_and_not_made_larger() -> None:
    from fishswarm.cli.swarm import start_warnings

    # A 100-m ball around the centre of the study's 1.78 x 1.78 x 1.17 m tank: nearly every
    # place drawn in it lies outside, and its fish start clipped onto the walls (at the
    # corners), piled there: neither warning may say to make the ball larger.
    walls, piled = start_warnings(Scenario(fish=6, spawn_radius=100.0))
    # The corners: √(0.89² + 0.89² + 0.585²) = 1.388 m from the centre, said rounded down so
    # that the radius given clears the warning.
    assert walls == (
        "the start ball's radius, 100 m, reaches past the tank's corners (1.38 m from its "
        "centre), and 6 of the 6 fish start on its walls: give a --spawn-radius of at most "
        "1.38 m, or --spawn tank to spread them evenly over the tank"
    )
    assert "--spawn tank" in piled and "--spawn-radius" not in piled
    # The study's formation start, a 1.3-m ball, stays within the corners: nothing to say.
    assert start_warnings(Scenario(fish=25, behavior="formation")) == []
    assert start_warnings(Scenario(fish=25, spawn_radius=1.38)) == []


def test_a_crowded_run_says_so_before_it_starts_and_runs_anyway(tmp_path: Path) -> None:
    summary = tmp_path / "s.json"
    crowded = ["--fish", "40", "--spawn-radius", "0.05", "--duration", "1", "--quiet"]
    result = _run("run", *crowded, *_outputs(tmp_path, summary))
    assert result.returncode == 0, result.stderr
    assert "fishswarm run: warning: the 40 fish start a median" in result.stderr
    assert json.loads(summary.read_text())["scenario"]["spawn_radius"] == pytest.approx(0.05)
    spread = _run("run", "--fish", "4", "--spawn", "tank", "--duration", "1", "--quiet",
                  *_outputs(tmp_path, summary))  # fmt: skip
    assert spread.returncode == 0, spread.stderr
    assert "warning" not in spread.stderr
    assert json.loads(summary.read_text())["scenario"]["spawn_region"] == "tank"


def test_preparing_a_folder_leaves_another_commands_probe_alone(tmp_path: Path) -> None:
    # Two worlds recording into one folder at once: each probed it with one file name, and
    # one removed the other's probe, which then said "cannot write there".
    from fishswarm.cli.common import prepare_folder

    theirs = tmp_path / ".fishswarm-write-test"
    theirs.write_bytes(b"")
    prepare_folder(tmp_path, "--record")
    assert theirs.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == [".fishswarm-write-test"]


def test_a_scenario_files_settings_that_the_run_ignores_are_named(tmp_path: Path) -> None:
    # The same as flags are refused; from a file (which may serve several runs) warned of.
    config = tmp_path / "c.toml"
    config.write_text(
        'switch_formation = "diamond"\nswitch_at = 1\njitter = 0.1\nfish = 3\ntolerance = 0.1\n'
        'slot_rule = "share"\n'
    )
    summary = tmp_path / "s.json"
    result = _run("run", "--config", str(config), "--duration", "1", "--quiet",
                  *_outputs(tmp_path, summary))  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert (
        f"fishswarm run: warning: {config}: tolerance, slot_rule, switch_formation, switch_at "
        "apply only with "
        "behavior formation, and this run's behavior is dispersion: here they change nothing"
    ) in result.stderr
    assert (
        f"fishswarm run: warning: {config}: jitter applies only with time_mode jitter, and "
        "this run's time_mode is lockstep: here it changes nothing"
    ) in result.stderr
    # With the behaviour they belong to, nothing to say of them.
    formed = _run("run", "--config", str(config), "--behavior", "formation", "--duration", "1",
                  "--time", "jitter", "--no-flags", "--quiet",
                  *_outputs(tmp_path, summary))  # fmt: skip
    assert formed.returncode == 0, formed.stderr
    assert "warning" not in formed.stderr, formed.stderr


def test_a_setting_that_needs_two_others_is_named_when_the_second_is_missing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # A formation run's file: effort_margin needs rotate_effort, switch_at a shape to switch
    # to, and the flag medium flags (turned off on the command line).
    from fishswarm.cli.parsers import build_parser, scenario_from

    config = tmp_path / "c.toml"
    config.write_text(
        'behavior = "formation"\neffort_margin = 2\nswitch_at = 1\nflag_medium = "light"\n'
    )
    args = build_parser().parse_args(["run", "--config", str(config), "--no-flags"])
    scenario_from(args)
    assert capsys.readouterr().err.splitlines() == [
        f"fishswarm run: warning: {config}: flag_medium applies only with flags true, and "
        "this run's flags is false: here it changes nothing",
        f"fishswarm run: warning: {config}: effort_margin applies only with rotate_effort "
        "true, and this run's rotate_effort is false: here it changes nothing",
        f"fishswarm run: warning: {config}: switch_at applies only with switch_formation "
        "set, and this run's switch_formation is none: here it changes nothing",
    ]
    # With what they need, nothing to say of them.
    config.write_text(
        'behavior = "formation"\neffort_margin = 2\nswitch_at = 1\nflag_medium = "channel"\n'
        'rotate_effort = true\nswitch_formation = "diamond"\n'
    )
    scenario_from(build_parser().parse_args(["run", "--config", str(config)]))
    assert capsys.readouterr().err == ""
    # Flags turned off by the file, not by --no-flags: the flag says so, by the file's name.
    config.write_text('behavior = "formation"\nflags = false\n')
    with pytest.raises(ConfigError) as refused:
        scenario_from(build_parser().parse_args(["run", "--config", str(config),
                                                 "--flag-medium", "light"]))  # fmt: skip
    assert str(refused.value) == (
        "--flag-medium applies only with flags true, and the scenario file's flags is false: "
        "leave --flag-medium out, or set flags = true in the file"
    )
    # A file refused alone, checked again with the flags on top: a flag's own error is named
    # by the flag, not blamed on the file.
    config.write_text("duration = 30\nbehavior = \"formation\"\nswitch_formation = \"line\"\n"
                      "switch_at = 50\n")  # fmt: skip
    with pytest.raises(ConfigError, match=r"^--period: control_period must be a positive"):
        scenario_from(build_parser().parse_args(["run", "--config", str(config),
                                                 "--period", "-1"]))  # fmt: skip


def test_a_run_says_which_study_code_switches_only_experiments_act_on(tmp_path: Path) -> None:
    summary = tmp_path / "s.json"
    named = ["--study-code", "drag,side-settings,mean-distance", "--fish", "3"]
    result = _run("run", *named, "--duration", "1", "--quiet", *_outputs(tmp_path, summary))
    assert result.returncode == 0, result.stderr
    assert (
        "fishswarm run: warning: the study-code switch(es) side-settings, mean-distance apply "
        "to 'fishswarm experiment' only: here they change nothing" in result.stderr
    )
    # The study-code profile turns every switch on: nothing named, nothing to say.
    profile = _run("run", "--profile", "study-code", "--fish", "3", "--duration", "1",
                   "--quiet", *_outputs(tmp_path, summary))  # fmt: skip
    assert profile.returncode == 0, profile.stderr
    assert "warning" not in profile.stderr


@pytest.mark.slow
def test_a_run_in_which_the_watchdog_stopped_fish_says_so_and_exits_4(tmp_path: Path) -> None:
    # Realtime at 1 Hz: perceptions (and the world's pulses) a second apart, against a
    # watchdog of 0.3 s: every fish is stopped between ticks.
    summary = tmp_path / "s.json"
    result = _run(
        "run",
        "--fish",
        "2",
        "--duration",
        "2",
        "--time",
        "realtime",
        "--perception-timeout",
        "0.3",
        "--quiet",
        *_outputs(tmp_path, summary),
        timeout=60,
    )
    assert result.returncode == 4, result.stderr
    # Said at the start too: such a watchdog cannot but fire.
    assert (
        "fishswarm run: warning: --perception-timeout 0.3 will stop the fins between two signs "
        "of life of the world (its pulse comes every 1 s), and the run will end 'degraded' "
        "(exit 4): give more than 1 s, e.g. --perception-timeout 2"
    ) in result.stderr
    assert "status: degraded — fish were stopped" in result.stderr
    written = json.loads(summary.read_text())
    assert written["status"] == "degraded" and written["fish"]["watchdog_stops"] >= 2
    # One warning per firing, naming both fish, not one line per fish.
    assert "2 fish (0, 1): no perception for 0.3 s" in result.stderr
    assert "fish 0: no perception" not in result.stderr


def test_an_orbit_run_reports_and_draws_its_circling(tmp_path: Path) -> None:
    summary = tmp_path / "s.json"
    outputs = _outputs(tmp_path, summary)
    args = ["--behavior", "milling", "--fish", "1", "--duration", "20", "--quiet", *outputs]
    result = _run("run", *args, timeout=60)
    assert result.returncode == 0, result.stderr
    # One fish: the distances are all zero, so the summary speaks of the orbit instead.
    assert "orbit around the post at (0.89, 0.89) m, R 0.45 m:" in result.stderr
    assert "revolutions, speed" in result.stderr and "centroid_distance" not in result.stderr
    orbit = json.loads(summary.read_text())["orbit"]
    assert orbit["post"][:2] == pytest.approx([0.89, 0.89])
    assert 0.3 < orbit["radius"] < 0.8 and orbit["revolutions"] > 0.1 and orbit["speed"] > 0
    picture = tmp_path / "orbit.png"
    plotted = _run("plot", str(tmp_path / "r.mcap"), "--out", str(picture))
    assert plotted.returncode == 0 and picture.stat().st_size > 10_000


def test_bad_config_files_are_explained(tmp_path: Path) -> None:
    broken = tmp_path / "broken.toml"
    broken.write_text("fish = [\n")
    unknown = tmp_path / "unknown.toml"
    unknown.write_text("fishes = 3\n")
    wrong = tmp_path / "wrong.toml"
    wrong.write_text('fish = "three"\n')
    assert "is not valid TOML" in _run("run", "--config", str(broken), timeout=30).stderr
    result = _run("run", "--config", str(unknown), timeout=30)
    assert result.returncode == 2
    assert "unknown setting(s) fishes" in result.stderr
    assert "fish must be a whole number" in _run("run", "--config", str(wrong), timeout=30).stderr
    missing = _run("run", "--config", str(tmp_path / "none.toml"), timeout=30)
    assert missing.returncode == 2 and "does not exist" in missing.stderr


def test_a_robot_that_cannot_open_its_hardware_or_configuration_says_so(tmp_path: Path) -> None:
    # No Raspberry Pi here: gpiozero finds no pin factory.
    result = _run("robot", "--id", "1", "--connect", "tcp/127.0.0.1:9", timeout=30)
    assert result.returncode == 1
    assert "cannot open the BlueBot's hardware" in result.stderr
    assert "use --hardware mock" in result.stderr
    # Not a line for each pin library gpiozero tried before it gave up: the error says it.
    assert "PinFactoryFallback" not in result.stderr
    (said,) = result.stderr.strip().splitlines()
    # ... but the reasons it gave each, in the one line: the cause of a robot's failure.
    assert said.startswith("fishswarm robot: error:") and "Falling back from lgpio" in said
    broken = tmp_path / "zenoh.json5"
    broken.write_text("{ mode: ")
    result = _run(
        "robot", "--id", "1", "--hardware", "mock", "--zenoh-config", str(broken), timeout=30
    )
    # A bad file is a bad argument, as a missing one is: exit 2, before the robot starts.
    assert result.returncode == 2
    assert f"--zenoh-config: Zenoh configuration {broken} cannot be read" in result.stderr


@pytest.mark.slow
def test_a_non_recording_or_empty_file_fails_the_same_way_in_every_command(
    tmp_path: Path,
) -> None:
    bogus = tmp_path / "bogus.mcap"
    bogus.write_bytes(b"not an mcap file at all")
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    for path, message in (
        (bogus, "is not an MCAP recording (it does not start like one)"),
        (empty, "is empty (0 bytes): the run that wrote it ended before recording anything"),
    ):
        for command in (
            ["export", str(path), "--npz", str(tmp_path / "x.npz")],
            ["plot", str(path), "--out", str(tmp_path / "x.png")],
            ["animate", str(path), "--out", str(tmp_path / "x.gif")],
        ):
            result = _run(*command, timeout=30)
            assert result.returncode == 1, (command, result.stderr)
            assert f"{path} {message}" in result.stderr


@pytest.mark.slow
def test_a_run_killed_outright_leaves_a_recording_readable_to_its_last_chunk(
    tmp_path: Path,
) -> None:
    record = tmp_path / "killed.mcap"
    process = subprocess.Popen(
        [
            *FISHSWARM,
            "run",
            "--duration",
            "5000",
            "--quiet",
            "--listen",
            f"tcp/127.0.0.1:{free_port()}",
            "--record",
            str(record),
            "--summary",
            str(tmp_path / "killed.json"),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 60
        while not record.exists() or record.stat().st_size < 250_000:
            assert time.monotonic() < deadline, "the run recorded nothing in a minute"
            assert process.poll() is None, "the run ended before it was killed"
            time.sleep(0.05)
    finally:
        os.killpg(process.pid, signal.SIGKILL)  # the launcher and its workers, no clean-up
        process.wait(timeout=30)
    recording = read_recording(record)
    assert not recording.complete
    ticks = [s.tick for s in recording.snapshots]
    assert len(ticks) >= 50 and ticks == list(range(len(ticks)))
    assert recording.scenario["fish"] == 25
    exported = _run("export", str(record), "--npz", str(tmp_path / "k.npz"), timeout=60)
    assert exported.returncode == 0, exported.stderr
    assert f"warning: {record} was cut short" in exported.stderr
    assert f"read {len(ticks)} snapshots, up to tick {ticks[-1]}" in exported.stderr
    assert np.load(tmp_path / "k.npz")["pos"].shape == (len(ticks), 25, 3)
    plotted = _run("plot", str(record), "--out", str(tmp_path / "k.png"), timeout=120)
    assert plotted.returncode == 0 and "was cut short" in plotted.stderr


def test_a_run_that_cannot_open_its_router_keeps_the_last_runs_files(tmp_path: Path) -> None:
    import socket

    record, summary = tmp_path / "latest.mcap", tmp_path / "latest.json"
    record.write_bytes(b"the last run's recording")
    summary.write_text('{"status": "finished"}')
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = _run("run", "--fish", "2", "--duration", "2", "--quiet",
                      "--listen", f"tcp/127.0.0.1:{port}", "--record", str(record),
                      "--summary", str(summary), timeout=60)  # fmt: skip
    assert result.returncode == 1, result.stderr
    assert "cannot open a router session" in result.stderr
    assert record.read_bytes() == b"the last run's recording"
    assert summary.read_text() == '{"status": "finished"}'


def test_a_world_that_cannot_reach_its_router_names_no_recording(tmp_path: Path) -> None:
    record = tmp_path / "world.mcap"
    result = _run("world", "--connect", f"tcp/127.0.0.1:{free_port()}", "--connect-timeout",
                  "0.5", "--record", str(record), timeout=30)  # fmt: skip
    assert result.returncode == 1
    assert "is a fishswarm run or router listening there" in result.stderr
    assert not record.exists() and "recording:" not in result.stderr, result.stderr


def test_fish_alone_without_router_fails_clearly() -> None:
    result = _run(
        "fish",
        "--id",
        "3",
        "--connect",
        f"tcp/127.0.0.1:{free_port()}",
        "--connect-timeout",
        "0.5",
        timeout=30,
    )
    assert result.returncode == 1
    assert "is a fishswarm run or router listening there" in result.stderr
    # Zenoh's reason, without where in Zenoh's Rust source it was raised.
    assert "Unable to connect to any of" in result.stderr and ".rs:" not in result.stderr


def test_bad_school_name_is_explained() -> None:
    result = _run("fish", "--id", "3", "--school", "a/b", "--connect", "tcp/127.0.0.1:1")
    assert result.returncode == 2
    assert "school name 'a/b' is not valid: use 1 to 64 letters, digits" in result.stderr


@pytest.mark.parametrize("procs", ["0", "2"])  # the fish in the launcher's process, or not
def test_ctrl_c_stops_the_run_within_two_seconds(tmp_path: Path, procs: str) -> None:
    with subprocess.Popen(
        [
            *FISHSWARM,
            "run",
            "--fish",
            "5",
            "--duration",
            "1000000",
            "--procs",
            procs,
            "--listen",
            f"tcp/127.0.0.1:{free_port()}",
            "--record",
            str(tmp_path / "r.mcap"),
            "--summary",
            str(tmp_path / "s.json"),
        ],
        stderr=subprocess.PIPE,
        text=True,
    ) as process:
        try:
            assert process.stderr is not None
            deadline = time.monotonic() + 60
            while "tick" not in process.stderr.readline():
                assert time.monotonic() < deadline, "the run never started"
            process.send_signal(signal.SIGINT)
            code = process.wait(timeout=10)
        finally:
            if process.poll() is None:
                process.kill()
    assert code == 130
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["status"] == "interrupted", summary
    assert _no_worker_left()


@pytest.mark.parametrize("procs", ["0", "2"])
def test_sigterm_to_the_process_group_mid_run_keeps_the_fish_counters(
    tmp_path: Path, procs: str
) -> None:
    with subprocess.Popen(
        [*FISHSWARM, "run", "--fish", "4", "--duration", "1000000", "--procs", procs,
         "--time", "realtime", "--period", "0.2", "--listen", f"tcp/127.0.0.1:{free_port()}",
         "--record", str(tmp_path / "r.mcap"), "--summary", str(tmp_path / "s.json")],
        stderr=subprocess.PIPE, text=True, start_new_session=True,
    ) as process:  # fmt: skip
        try:
            assert process.stderr is not None
            deadline = time.monotonic() + 60
            while "tick" not in process.stderr.readline():
                assert time.monotonic() < deadline, "the run never started"
            time.sleep(1.0)
            os.killpg(process.pid, signal.SIGTERM)
            _, errors = process.communicate(timeout=20)
        finally:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGKILL)
    assert process.returncode == 130, errors
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["status"] == "interrupted" and summary["counts"]["lost_fish"] == 0
    assert summary["fish"]["commands"] >= 4 * 3, summary["fish"]


def _no_worker_left() -> bool:
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                command = (entry / "cmdline").read_bytes()
            except OSError:
                continue
            if b"multiprocessing.spawn" in command and str(os.getpid()).encode() not in command:
                parent = (entry / "stat").read_text().split()[3]
                if parent == "1":
                    return False
    return True


def test_run_a_learned_replica_in_the_swarm(tmp_path: Path) -> None:
    model = tmp_path / "best_replica.npz"
    weights = np.random.default_rng(3).normal(0, 1, 21)
    np.savez(model, weights=weights, settings=np.array(json.dumps({"behavior": "aggregation"})))
    summary = tmp_path / "s.json"
    result = _run(
        "run",
        "--behavior",
        "replica",
        "--model",
        str(model),
        "--fish",
        "5",
        "--duration",
        "3",
        "--quiet",
        *_outputs(tmp_path, summary),
    )
    assert result.returncode == 0, result.stderr
    data = json.loads(summary.read_text())
    assert data["scenario"]["behavior"] == "replica"
    assert data["counts"]["ticks"] == 3
    # The replica swam as it does in the batch engine, bit for bit, and it did swim.
    scenario = Scenario(behavior="replica", model=str(model), fish=5, duration=3.0)
    recorded = read_recording(tmp_path / "r.mcap").arrays()["pos"]
    np.testing.assert_array_equal(recorded, simulate_batch(scenario).position)
    assert np.abs(recorded[-1] - recorded[0]).max() > 0.01


def test_replica_without_a_model_is_explained(tmp_path: Path) -> None:
    result = _run("run", "--behavior", "replica", timeout=30)
    assert result.returncode == 2
    assert "needs a learned model" in result.stderr
    bogus = tmp_path / "bogus.npz"
    bogus.write_bytes(b"nope")
    result = _run("run", "--behavior", "replica", "--model", str(bogus), timeout=30)
    assert result.returncode == 2
    assert "is not a learned replica" in result.stderr


def test_a_formation_run_reports_its_shape_and_flags(tmp_path: Path) -> None:
    summary = tmp_path / "s.json"
    result = _run(
        "run",
        "--config",
        str(Path(__file__).resolve().parents[2] / "experiments" / "formation.toml"),
        "--fish",
        "6",
        "--duration",
        "5",
        "--quiet",
        *_outputs(tmp_path, summary),
    )
    assert result.returncode == 0, result.stderr
    assert "formation pyramid: shape error" in result.stderr
    assert (
        "the study's fitness ΣF:" in result.stderr and "summed over 11 snapshots" in result.stderr
    )

    def refuse(word: str) -> None:
        raise ValueError(f"{word} is not JSON")

    data = json.loads(summary.read_text(), parse_constant=refuse)
    formation = data["formation"]
    assert 0.0 <= formation["joined_fraction"] <= 1.0 and formation["shape_error"] > 0.0
    assert formation["fitness_total"] >= formation["fitness"] > 0.0
    # Every fish flags at every decision (2 Hz for 5 s); each flag reaches the 5 others.
    assert data["counts"]["broadcasts"] == 6 * 10
    assert data["counts"]["deliveries"] >= 5 * 6 * 9


@pytest.mark.slow
def test_an_operator_pauses_resumes_and_stops_a_run_from_another_process(tmp_path: Path) -> None:
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    summary = tmp_path / "s.json"
    run = subprocess.Popen(
        [*FISHSWARM, "run", "--fish", "3", "--duration", "100000", "--period", "0.25",
         "--time", "realtime", "--listen", endpoint, "--quiet", "--record",
         str(tmp_path / "r.mcap"), "--summary", str(summary)],
        stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    said = re.compile(r"^swarm 'default': (\w+) at tick (\d+) \(t = [\d.]+ s\), (\d+) fish$")

    def ask(action: str) -> tuple[str, int, int]:
        done = _run("control", action, "--connect", endpoint, timeout=30)
        assert done.returncode == 0, done.stderr
        match = said.match(done.stdout.strip())
        assert match is not None, done.stdout
        return match[1], int(match[2]), int(match[3])

    try:
        wait_for_port(port)
        deadline = time.monotonic() + 30
        while True:  # until the world answers, its three fish up and a tick gone by
            status = _run("control", "status", "--connect", endpoint, timeout=30)
            if status.returncode == 0 and re.search(
                r"running at tick [1-9]\d*.*3 fish", status.stdout
            ):
                break
            assert time.monotonic() < deadline, status.stderr
            time.sleep(0.2)
        assert ask("pause")[0] == "pausing"  # the tick under way is answered first
        time.sleep(1.0)  # four periods, held
        held = ask("status")
        time.sleep(1.0)
        assert ask("status") == held and held[0] == "paused"
        state, tick, fish = ask("resume")
        assert (state, tick, fish) == ("running", held[1], 3)
        time.sleep(1.0)
        state, stopped_at, _ = ask("stop")
        assert state == "stopping" and stopped_at > held[1]
        _, errors = run.communicate(timeout=30)
    finally:
        if run.poll() is None:
            run.kill()
            run.communicate(timeout=10)
    assert run.returncode == 0, errors
    data = json.loads(summary.read_text())
    assert data["status"] == "stopped" and data["counts"]["ticks"] == stopped_at
    # Held about 2 s: left out of the real-time factor (realtime: about 1× of the rest).
    assert 1.5 < data["paused_time"] < data["loop_time"] - 0.5
    assert data["real_time_factor"] == pytest.approx(
        stopped_at * 0.25 / (data["loop_time"] - data["paused_time"])
    )
    assert 0.7 < data["real_time_factor"] <= 1.05
    assert re.search(r"\(ticks [\d.]+ s of it, paused [\d.]+ s: [\d.]+× real time\)", errors)
    gone = _run("control", "status", "--connect", endpoint, "--connect-timeout", "2")
    assert gone.returncode == 1 and "error:" in gone.stderr


def test_control_with_no_world_running_says_no_world_answered() -> None:
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    router = subprocess.Popen([*FISHSWARM, "router", "--listen", endpoint],
                              stderr=subprocess.DEVNULL)  # fmt: skip
    try:
        wait_for_port(port)
        asked = _run("control", "pause", "--connect", endpoint, "--swarm", "tank2", timeout=60)
    finally:
        router.terminate()
        router.wait(timeout=30)
    assert asked.returncode == 1 and asked.stdout == ""
    assert asked.stderr == (
        f"fishswarm control: error: no world of swarm 'tank2' answered on {endpoint}: is a "
        "run going, and under this --swarm?\n"
    )


@pytest.mark.slow
def test_an_operator_switches_a_running_schools_formation(tmp_path: Path) -> None:
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    config = Path(__file__).resolve().parents[2] / "experiments" / "formation.toml"
    run = subprocess.Popen(
        [*FISHSWARM, "run", "--config", str(config), "--fish", "6", "--duration", "100000",
         "--period", "0.5", "--time", "realtime", "--listen", endpoint, "--quiet",
         "--record", str(tmp_path / "r.mcap"), "--summary", str(tmp_path / "s.json")],
        stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        wait_for_port(port)
        deadline = time.monotonic() + 30
        while True:  # until the world answers with all six fish joined
            switch = _run("formation", "diamond", "--connect", endpoint, timeout=30)
            joined = switch.returncode == 0 and "6 fish" in switch.stdout
            if joined or time.monotonic() > deadline:
                break
            time.sleep(0.2)
        assert switch.returncode == 0, switch.stderr
        # What was done on stdout, as control's status is.
        assert "formation diamond from tick" in switch.stdout and "6 fish" in switch.stdout
        bad = _run("formation", "circle", "--connect", endpoint, timeout=30)
        assert bad.returncode == 2 and "invalid choice: 'circle'" in bad.stderr
        # Let a few snapshots come after the switch.
        time.sleep(2.0)
    finally:
        run.send_signal(signal.SIGINT)
        _, errors = run.communicate(timeout=20)
    assert run.returncode == 130, errors
    # The snapshots say when the fish were told to take the diamond, and the recording's
    # pictures measure them against it from then on.
    from fishswarm.cli.study import _animated_formation, _formations_of
    from fishswarm.study.recording import read_recording

    recording = read_recording(tmp_path / "r.mcap")
    shapes = [snapshot.formation for snapshot in recording.snapshots]
    first = shapes.index("diamond")
    assert 0 < first < len(shapes) - 2
    assert set(shapes[:first]) == {None} and set(shapes[first:]) == {"diamond"}
    targets = _formations_of(recording)
    assert targets is not None
    assert targets[0].slots is not None and targets[-1].slots is not None
    assert targets[0].slots.shape != targets[-1].slots.shape or not np.allclose(
        targets[0].slots, targets[-1].slots
    )
    animated = _animated_formation(recording)
    np.testing.assert_array_equal(animated["formation"].slots, targets[0].slots)
    ((since, switched),) = animated["switches"]
    assert since == recording.snapshots[first].time
    np.testing.assert_array_equal(switched.slots, targets[-1].slots)


def test_a_switch_a_running_world_cannot_make_fails_with_why(tmp_path: Path) -> None:
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    run = subprocess.Popen(
        [*FISHSWARM, "run", "--fish", "3", "--duration", "100000", "--period", "0.5",
         "--time", "realtime", "--listen", endpoint, "--quiet",
         "--record", str(tmp_path / "r.mcap"), "--summary", str(tmp_path / "s.json")],
        stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        wait_for_port(port)
        deadline = time.monotonic() + 30
        while True:  # until the world answers
            switch = _run("formation", "diamond", "--connect", endpoint, timeout=30)
            if "no world" not in switch.stderr or time.monotonic() > deadline:
                break
            time.sleep(0.2)
        assert switch.returncode == 1, switch.stderr
        assert (
            "the world did not switch to diamond: the fish run dispersion, not a formation"
            in switch.stderr
        )
    finally:
        run.send_signal(signal.SIGINT)
        run.communicate(timeout=20)


def test_version_descriptions_and_quiet_world() -> None:
    version = _run("--version")
    assert version.returncode == 0 and version.stdout.strip() == "fishswarm 0.1.0"
    for command, words in (("channel", "broadcast medium"), ("router", "Zenoh router that")):
        text = _run(command, "--help").stdout
        assert words in " ".join(text.split()), text
    assert "--quiet" in _run("world", "--help").stdout


@pytest.mark.parametrize(("engine", "jobs"), [("batch", "2"), ("actors", "1")])
def test_an_experiment_stopped_with_ctrl_c_keeps_what_finished(
    tmp_path: Path, engine: str, jobs: str
) -> None:
    # With the actors in this process (one job), Ctrl-C comes out of the run's trio in an
    # exception group: it printed a traceback, exited 1 and wrote nothing.
    out = tmp_path / "blindspot"
    sweep = subprocess.Popen(
        [*FISHSWARM, "experiment", "blindspot", "--engine", engine, "--jobs", jobs,
         "--duration", "5", "--out", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert sweep.stderr is not None
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:  # until the first runs have finished
            line = sweep.stderr.readline()
            if " run 2/" in line or not line:
                break
        if engine == "actors":
            time.sleep(0.25)  # into the next run (a line is printed between two runs)
        sweep.send_signal(signal.SIGINT)
        _, errors = sweep.communicate(timeout=60)
    finally:
        sweep.kill()
    assert sweep.returncode == 130, errors
    assert "interrupted after" in errors and "marked incomplete" in errors
    assert "Traceback" not in errors
    summary = json.loads((out / "summary.json").read_text())
    assert not summary["complete"] and 2 <= summary["runs_done"] < summary["runs_total"] == 20
    assert "**Incomplete**" in (out / "table.md").read_text()
    assert (out / "metrics_vs_parameter.png").stat().st_size > 0


@pytest.mark.parametrize("command", ["world", "observe"])
def test_a_command_that_cannot_reach_its_router_writes_no_recording(
    command: str, tmp_path: Path
) -> None:
    record = tmp_path / "never.mcap"
    endpoint = f"tcp/127.0.0.1:{free_port()}"  # nothing listens there
    result = _run(
        command, "--connect", endpoint, "--connect-timeout", "0.5", "--record", str(record),
        timeout=60,
    )  # fmt: skip
    assert result.returncode == 1
    assert "is a fishswarm run or router listening there?" in result.stderr
    assert not record.exists()


def test_the_speed_animate_advises_is_one_it_then_accepts() -> None:
    from fishswarm.cli.study import MAX_FRAMES, _rounded_up

    # A 15-s run at 25 frames a second needs --speed 0.01875 or more: advised as 0.0188
    # (0.0187 would make 20 053 frames, and be refused again).
    assert _rounded_up(15 / (MAX_FRAMES * 0.04)) == 0.0188
    assert MAX_FRAMES >= 15 / (0.0188 * 0.04)
    assert _rounded_up(0.002) == 0.002  # on the grid already: not a step up


@pytest.mark.parametrize(
    "command",
    [["robots"], ["robot", "--id", "0", "--hardware", "mock"], ["observe"]],
    ids=["robots", "robot", "observe"],
)
def test_a_command_waiting_for_its_router_forever_ends_at_once_on_sigterm(
    command: list[str],
) -> None:
    """A robot's service waits for its router forever (--connect-timeout -1); systemd's stop
    (SIGTERM) or Ctrl-C must not wait for a router that may never come: exit 130 at once
    (it used to ignore both until killed)."""
    port = free_port()  # nothing listens there
    with subprocess.Popen(
        [*FISHSWARM, *command, "--connect", f"tcp/127.0.0.1:{port}", "--connect-timeout", "-1"],
        stderr=subprocess.PIPE,
        text=True,
    ) as process:
        try:
            # Its worker thread (named after the function it runs) is in zenoh.open.
            threads = Path(f"/proc/{process.pid}/task")
            deadline = time.monotonic() + 60
            while not any(
                (task / "comm").read_text().startswith("open_unless")
                for task in threads.iterdir()
                if (task / "comm").exists()
            ):
                assert time.monotonic() < deadline, "it never began to open its session"
                time.sleep(0.1)
            time.sleep(0.5)
            process.send_signal(signal.SIGTERM)
            code = process.wait(timeout=10)  # it used to wait until killed
        finally:
            if process.poll() is None:
                process.kill()
        assert process.stderr is not None
        errors = process.stderr.read()
    assert code == 130 and errors.rstrip().endswith("fishswarm: interrupted"), errors


def test_a_standalone_worlds_turn_delay_comes_from_its_command_line(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """--turn-delay reaches the world's settings; without it, the default (0.1 s)."""
    from fishswarm.cli import main, swarm
    from fishswarm.sim.scenario import TURN_DELAY

    class Made(Exception):
        pass

    made: list[Any] = []

    def world(settings: Any) -> Any:
        made.append(settings)
        raise Made

    monkeypatch.setattr(swarm, "World", world)
    for words, delay in ((["--turn-delay", "0.75"], 0.75), ([], TURN_DELAY)):
        with pytest.raises(Made):
            main(["world", "--fish", "2", *words])
        assert made.pop().turn_delay == delay


def test_a_watchdog_shorter_than_the_worlds_signs_of_life_is_warned_of() -> None:
    from fishswarm.cli.swarm import _watchdog_warning
    from fishswarm.sim.scenario import Scenario

    # The world pulses every second; in real time at 2 Hz a perception comes every 0.5 s.
    fast = Scenario(time_mode="realtime", control_period=0.5)
    assert _watchdog_warning(0.6, fast) is None
    warning = _watchdog_warning(0.5, fast)
    assert warning is not None and "a perception comes every control period, 0.5 s" in warning
    assert "e.g. --perception-timeout 1" in warning
    # At 0.5 Hz, or in lockstep (a slow tick may leave only the pulse): the pulse's second.
    for scenario in (Scenario(time_mode="realtime", control_period=2.0), Scenario()):
        warning = _watchdog_warning(1.0, scenario)
        assert warning is not None and "its pulse comes every 1 s" in warning
        assert _watchdog_warning(1.5, scenario) is None
    assert _watchdog_warning(5.0, Scenario()) is None  # the default watchdog
    # Jitter is not paced by the wall clock: only the pulse is sure to come.
    assert _watchdog_warning(0.6, Scenario(time_mode="jitter", control_period=0.5)) is not None


def test_a_secured_run_without_its_certificates_says_so_before_it_starts(tmp_path: Path) -> None:
    empty = tmp_path / "keys"
    empty.mkdir()
    outputs = ["--record", str(tmp_path / "r.mcap"), "--summary", str(tmp_path / "s.json")]
    listen = f"tls/127.0.0.1:{free_port()}"
    result = _run("run", "--secure", str(empty), "--listen", listen, "--quiet", *outputs)
    assert result.returncode == 1 and "Traceback" not in result.stderr
    assert f"{empty}/ca.pem is missing: no certificate for 'router'" in result.stderr
    assert "listening on" not in result.stderr  # the run was not announced


def test_an_edited_copy_of_an_experiment_keeps_its_own_results(tmp_path: Path) -> None:
    from fishswarm.cli.study import _results_name

    shipped = Path(__file__).parents[2] / "experiments" / "orbit.toml"
    copy = tmp_path / "my.toml"
    copy.write_text(shipped.read_text())  # the same name = "orbit" inside
    assert _results_name("orbit", "orbit") == "orbit"
    assert _results_name(str(shipped), "orbit") == "orbit"
    assert _results_name(str(copy), "orbit") == "my"


def test_ctrl_c_while_a_report_is_written_waits_for_it() -> None:
    # An experiment's report (tables and pictures) is written whole: Ctrl-C meanwhile is
    # noted, and acted on after (a walkthrough's interrupted sweep lacked tracks.png while
    # its summary said complete).
    from fishswarm.cli.study import _interrupt_deferred

    before = signal.getsignal(signal.SIGINT)
    with _interrupt_deferred() as came:
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.01)  # the handler runs between bytecodes of this thread
        written = True
    assert written and came == [signal.SIGINT]
    assert signal.getsignal(signal.SIGINT) is before


def test_an_experiment_interrupted_as_its_last_run_ends_says_all_runs_are_done(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    # Ctrl-C came after the last run: nothing is missing, and the report says complete;
    # the message said "marked incomplete" all the same.
    from fishswarm.cli import main
    from fishswarm.study import sweep
    from fishswarm.study.experiment import find

    real = sweep.sweep_experiment

    def interrupted_at_the_end(*args: Any, **kwargs: Any) -> Any:
        outcomes = real(*args, **kwargs)
        raise sweep.SweepInterrupted(outcomes, len(outcomes))

    monkeypatch.setattr(sweep, "sweep_experiment", interrupted_at_the_end)
    out = tmp_path / "m"
    code = main(["experiment", "blindspot", "--engine", "batch", "--jobs", "1", "--seeds", "1",
                 "--duration", "2", "--out", str(out), "--quiet"])  # fmt: skip
    said = capsys.readouterr().err
    total = len(find("blindspot").with_changes(seeds=1).runs())
    assert code == 130
    assert f"interrupted as the last run ended: all {total} runs done" in said, said
    assert "marked incomplete" not in said
    assert json.loads((out / "summary.json").read_text())["complete"] is True


def test_an_experiment_run_again_says_it_replaces_the_earlier_results(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # A run of the same experiment replaced the study's results without a word.
    from fishswarm.cli import main

    out = tmp_path / "b"
    command = ["experiment", "blindspot", "--engine", "batch", "--jobs", "1", "--seeds", "1",
               "--duration", "2", "--out", str(out), "--quiet"]  # fmt: skip
    assert main(command) == 0
    assert "replacing" not in capsys.readouterr().err
    assert main(command) == 0
    said = capsys.readouterr().err.splitlines()[0]
    assert re.fullmatch(
        rf"fishswarm experiment: note: replacing the results in {re.escape(str(out))} \(of "
        r"\d{4}-\d\d-\d\d \d\d:\d\d\); give --out to keep them",
        said,
    ), said


def test_a_map_larger_than_the_tank_or_places_closer_than_a_body_are_warned_of() -> None:
    from fishswarm.cli.swarm import map_warnings

    forming = Scenario(behavior="formation", fish=15, spacing=0.25)
    assert map_warnings(forming) == []  # the pyramid of the README: 0.87 × 1.00 m
    assert map_warnings(Scenario(fish=15, spacing=0.05)) == []  # not a formation
    # A column of 15 at 0.25 m is 14 spacings long, 3.5 m in a 1.78-m tank.
    assert map_warnings(forming.replace(formation="column")) == [
        "a column of 15 fish at a spacing of 0.25 m spans 3.50 × 0.00 × 0.00 m, more than the "
        "tank's 1.78 × 1.78 × 1.17 m: the fish cannot all take their places (give fewer "
        "--fish, a smaller --spacing, or another --formation)"
    ]
    # Six fish, 1.25 m: it fits, and turned by 45° too (0.88 × 0.88 m).
    six = forming.replace(formation="column", fish=6)
    assert map_warnings(six) == map_warnings(six.replace(formation_heading_deg=45.0)) == []
    # A switch to a shape that does not fit is warned of too.
    assert "a column of 15 fish" in map_warnings(forming.replace(switch_formation="column"))[0]
    assert map_warnings(forming.replace(spacing=0.1)) == [
        "the spacing, 0.1 m, is less than a BlueBot's length (13 cm): fish in their places "
        "would touch (give a --spacing of at least 0.13 m)"
    ]


def test_a_local_shape_with_too_few_fish_is_warned_of_and_its_error_said_unmeasured(
    tmp_path: Path,
) -> None:
    from fishswarm.cli.swarm import local_shape_warning

    assert local_shape_warning(Scenario(fish=3, behavior="formation", formation="triangle")) is None
    assert local_shape_warning(Scenario(fish=2, behavior="aggregation")) is None
    assert local_shape_warning(
        Scenario(fish=3, behavior="formation", formation="triangle", switch_formation="tetrahedron")
    ) == (
        "a tetrahedron needs at least 4 fish: with 3 fish none can complete it, and the shape "
        "error is not measured (give more --fish)"
    )
    summary = tmp_path / "s.json"
    result = _run("run", "--behavior", "formation", "--formation", "triangle", "--fish", "2",
                  "--duration", "2", *_outputs(tmp_path, summary))  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "warning: a triangle needs at least 3 fish: with 2 fish none can" in result.stderr
    # The summary goes to stderr, beside the warnings (stdout is left to data).
    assert "formation triangle: shape error not measured (too few fish), 0 % joined" in (
        result.stderr
    )


def test_a_summary_of_a_world_left_without_fish_says_so_instead_of_nan(tmp_path: Path) -> None:
    from fishswarm.cli.swarm import _summary_text

    summary = tmp_path / "s.json"
    result = _run("run", "--fish", "3", "--behavior", "formation", "--duration", "1", "--quiet",
                  *_outputs(tmp_path, summary))  # fmt: skip
    assert result.returncode == 0, result.stderr
    data = json.loads(summary.read_text())
    # As a world that lost every fish ends: its last distances are not defined (null), its
    # formation metrics not a number.
    for values in data["metrics"].values():
        values["final"], values["change_percent"] = None, None
    for name in ("shape_error", "joined_fraction", "lattice_energy", "collisions"):
        data["formation"][name] = math.nan
    text = _summary_text(data)
    assert "centroid_distance: " in text and "→ none (no fish)" in text
    assert (
        "formation pyramid: shape error not measured (too few fish), none joined (no fish) "
        "(never 90 %), lattice energy none (no fish), collisions at most"
    ) in text
    assert "nan" not in text
    # A run switched to another shape counts its 90 % from the switch.
    data["formation"].update(
        shape_error=0.02, joined_fraction=1.0, lattice_energy=0.002, fitness=0.25,
        fitness_total=76.3, snapshots=71, time_to_90_percent_joined=44.0,
        shapes=[{"time": 0.0, "shape": "pyramid"}, {"time": 25.0, "shape": "diamond"}],
    )  # fmt: skip
    text = _summary_text(data)
    assert "pyramid → diamond (from 25 s): shape error 0.020 m, 100 % joined (90 % first at " \
        "44 s, 19 s after the switch)" in text  # fmt: skip
    assert "76.3 m summed over 71 snapshots (from 25 s, the last shape's)" in text
    data["formation"]["time_to_90_percent_joined"] = None
    assert "(never 90 % since the switch)" in _summary_text(data)
    data["formation"]["shapes"] = data["formation"]["shapes"][:1]
    assert "(never 90 %)" in _summary_text(data)
    assert "the last shape's" not in _summary_text(data)


def test_a_secured_command_without_cryptography_says_which_extra_to_install(
    tmp_path: Path,
) -> None:
    # The core install has no cryptography: every --secure command ended in a traceback.
    blocked = (
        "import sys; sys.modules['cryptography'] = None\n"
        "from fishswarm.cli import main\nsys.exit(main(sys.argv[1:]))"
    )
    (tmp_path / "keys").mkdir()
    for args in (
        ["secure", "init", str(tmp_path / "new")],
        ["observe", "--secure", str(tmp_path / "keys"), "--connect", "tls/127.0.0.1:1"],
    ):
        result = subprocess.run(
            [sys.executable, "-c", blocked, *args], capture_output=True, text=True, timeout=60
        )
        assert result.returncode == 1, result.stderr
        assert "Traceback" not in result.stderr
        assert result.stderr.rstrip().endswith(
            "error: a secured swarm's certificates need the cryptography package: pip install "
            "-e '.[secure]' (on a robot: apt install python3-cryptography; deploy/ does)"
        )


def test_a_large_swarm_without_numba_is_warned_of_with_the_extra_to_install(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from fishswarm.cli.swarm import start_warnings
    from fishswarm.sim import kernels

    spread = Scenario(fish=kernels.COMPILED_MIN_FISH, spawn_region="tank")
    assert not any("numba" in warning for warning in start_warnings(spread))
    monkeypatch.setattr(kernels, "available", lambda: False)
    (said,) = [warning for warning in start_warnings(spread) if "numba" in warning]
    assert said.startswith(f"numba is not installed: the world sees {spread.fish} fish on the ")
    assert said.endswith("pip install -e '.[fast]'")
    small = Scenario(fish=kernels.COMPILED_MIN_FISH - 1, spawn_region="tank")
    assert not any("numba" in warning for warning in start_warnings(small))


def test_a_behaviours_own_settings_come_from_the_file_and_the_command_line(
    tmp_path: Path,
) -> None:
    from fishswarm.cli.parsers import build_parser, scenario_from
    from tests.behaviors import example_plugin

    example_plugin.registered()  # nearest: distance 0.26, cruise 0.52 m by default

    def scenario(*args: str) -> Scenario:
        return scenario_from(build_parser().parse_args(["run", *args]))

    ran = scenario("--behavior", "nearest", "--behavior-setting", "distance=1")
    assert ran.behavior_settings == (("distance", 1.0),)
    # Each NAME=VALUE over the file's table; the file's others kept.
    config = tmp_path / "s.toml"
    config.write_text(
        'behavior = "nearest"\nbehavior_settings = { distance = 0.3, cruise = 0.4 }\n'
    )
    assert scenario("--config", str(config)).behavior_settings == (
        ("cruise", 0.4),
        ("distance", 0.3),
    )
    ran = scenario("--config", str(config), "--behavior-setting", "cruise=0.9")
    assert ran.behavior_settings == (("cruise", 0.9), ("distance", 0.3))
    named = re.escape(
        "--behavior-setting: distance of nearest must be a finite number (its default is "
        '0.26), got "far"'
    )
    with pytest.raises(ConfigError, match=f"^{named}$"):
        scenario("--behavior", "nearest", "--behavior-setting", "distance=far")
    named = "--behavior-setting: dispersion has no setting 'distance'; it has no settings"
    with pytest.raises(ConfigError, match=f"^{named}"):
        scenario("--behavior-setting", "distance=1")
    # The file's table, for its behaviour, under another --behavior: said so.
    with pytest.raises(ConfigError) as refused:
        scenario("--config", str(config), "--behavior", "aggregation")
    assert str(refused.value) == (
        f"{config}: behavior_settings: aggregation has no setting 'cruise'; it has no settings "
        "of its own (the file's behavior_settings are for its behavior nearest, and --behavior "
        "makes it aggregation: leave one of them out)"
    )


def test_a_behaviour_setting_that_is_not_name_equals_value_is_refused() -> None:
    result = _run("run", "--behavior-setting", "distance")
    assert result.returncode == 2
    assert "argument --behavior-setting: 'distance' is not NAME=VALUE, e.g. gain=0.5" in (
        result.stderr
    )
