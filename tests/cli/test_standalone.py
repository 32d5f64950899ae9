"""Each actor alone, as separate processes on one router: what a tank with robots and a
remote observer looks like, on 127.0.0.1."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fishswarm.study.recording import read_recording
from tests.cli.processes import routed_commands, started_commands
from tests.conftest import Lines, end_processes, free_port, wait_for_port

pytestmark = pytest.mark.integration

FISHSWARM = [sys.executable, "-m", "fishswarm"]


@pytest.mark.slow
def test_router_world_fish_and_remote_observer_as_separate_processes(tmp_path: Path) -> None:
    record = tmp_path / "observed.mcap"
    world_record = tmp_path / "world.mcap"
    with routed_commands() as (endpoint, start):
        observer = start("observe", "--connect", endpoint, "--ticks", "6", "--record", str(record))
        # Without --ticks an observer ends with the run: when the world leaves.
        until_the_end = start("observe", "--connect", endpoint)
        start("fish", "--id", "0", "--id", "1", "--school", "pair", "--connect", endpoint)
        start("fish", "--id", "2", "--connect", endpoint)
        start("channel", "--connect", endpoint)
        # Three world runs in a row, served by the same fish processes: a fish that answered
        # tick 6 of one run answers tick 0 of the next.
        for duration in ("6", "4", "5"):
            world = subprocess.run(
                [
                    *FISHSWARM,
                    "world",
                    "--connect",
                    endpoint,
                    "--fish",
                    "3",
                    "--duration",
                    duration,
                    "--start-timeout",
                    "60",
                    *(["--record", str(world_record)] if duration == "5" else []),
                ],
                capture_output=True,
                text=True,
                timeout=120,
                check=False,
            )
            assert world.returncode == 0, world.stderr
            statistics = json.loads(world.stderr.strip().splitlines()[-1])
            assert statistics["ticks"] == int(duration)
            assert f"status: finished at tick {duration} ({duration} s simulated, " in (
                world.stderr
            )
            assert " wall time); 0 fish lost, 0 messages rejected by the world" in world.stderr
            assert statistics["lost_fish"] == 0
            assert statistics["rejected"] == {}
        _, observer_errors = observer.communicate(timeout=30)
        assert observer.returncode == 0, observer_errors
        _, end_errors = until_the_end.communicate(timeout=30)
        assert until_the_end.returncode == 0, end_errors
        assert re.search(r"observed ticks \d+–6 \(\d+ snapshots\), 3 fish at the end", end_errors)
    # The world records its own run, with its scenario: plot draws it.
    own = read_recording(world_record)
    assert own.complete and [s.tick for s in own.snapshots] == [0, 1, 2, 3, 4, 5]
    assert own.scenario["fish"] == 3 and own.scenario["duration"] == 5
    plotted = subprocess.run(
        [*FISHSWARM, "plot", str(world_record), "--out", str(tmp_path / "world.png")],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert plotted.returncode == 0, plotted.stderr
    recording = read_recording(record)
    assert [s.tick for s in recording.snapshots][-1] == 6
    # Up before the world, the observer asked it what runs, and recorded that.
    assert recording.scenario["fish"] == 3 and recording.scenario["duration"] == 6
    assert recording.snapshots[-1].ids.tolist() == [0, 1, 2]
    assert any(e["role"] == "fish" for e in recording.events)


@pytest.mark.slow
def test_a_secured_swarm_runs_and_is_watched_as_a_plain_one(tmp_path: Path) -> None:
    import numpy as np

    from fishswarm.sim.engine import simulate_batch
    from fishswarm.sim.scenario import Scenario

    secure = tmp_path / "secure"
    made = subprocess.run(
        [*FISHSWARM, "secure", "init", str(secure), "--robots", "0", "1", "--observers", "lab"],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert made.returncode == 0, made.stderr
    port = free_port()
    endpoint = f"tls/127.0.0.1:{port}"
    record = tmp_path / "observed.mcap"
    processes: list[subprocess.Popen[str]] = []

    def start(*args: str) -> subprocess.Popen[str]:
        process = subprocess.Popen(
            [*FISHSWARM, *args, "--secure", str(secure)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        processes.append(process)
        return process

    try:
        start("router", "--listen", endpoint)
        wait_for_port(port)
        observer = start("observe", "--connect", endpoint, "--name", "lab", "--record", str(record))
        # The live view attaches as an observer too; it learns the run from the world.
        view = subprocess.Popen(
            [*FISHSWARM, "view", "--connect", endpoint, "--secure", str(secure), "--name", "lab",
             "--web-port", str(free_port()), "--grpc-port", str(free_port())],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        view_lines = Lines(view)
        view_lines.wait_for(r"following swarm 'default' on tls/127\.0\.0\.1:\d+$")
        # The world first: it waits for its fish, and meanwhile tells the view what runs.
        world = subprocess.Popen(
            [*FISHSWARM, "world", "--connect", endpoint, "--fish", "2", "--duration", "5",
             "--seed", "4", "--start-timeout", "60", "--secure", str(secure)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        processes.append(world)
        view_lines.wait_for(r"the world runs 2 fish, dispersion, 5 s")
        # An operator asks with the admin certificate: the world waits for its fish.
        status = subprocess.run(
            [*FISHSWARM, "control", "status", "--connect", endpoint, "--secure", str(secure)],
            capture_output=True, text=True, timeout=60, check=False,
        )  # fmt: skip
        assert status.returncode == 0, status.stderr
        assert status.stdout.startswith("swarm 'default': waiting at tick 0 "), status.stdout
        start("fish", "--id", "0", "--connect", endpoint)
        start("fish", "--id", "1", "--connect", endpoint)
        start("channel", "--connect", endpoint)
        _, world_errors = world.communicate(timeout=120)
        assert world.returncode == 0, world_errors
        statistics = json.loads(world_errors.strip().splitlines()[-1])
        assert statistics["ticks"] == 5 and statistics["lost_fish"] == 0
        _, observer_errors = observer.communicate(timeout=30)
        assert observer.returncode == 0, observer_errors
        shown = view_lines.wait_for(r"the run has ended \((\d+) snapshots shown\)")
        assert int(shown[1]) == 6  # ticks 0–5
        view.send_signal(signal.SIGINT)
        assert view.wait(timeout=30) == 0
        # Without a certificate a command does not try (Zenoh refusing an uncertified
        # client is tested in tests/actors/test_security.py): it says what is missing.
        bare = subprocess.run(
            [*FISHSWARM, "observe", "--connect", endpoint, "--connect-timeout", "2"],
            capture_output=True, text=True, timeout=60, check=False,
        )  # fmt: skip
        assert bare.returncode == 2 and "is a secured (tls/) endpoint: give --secure DIR" in (
            bare.stderr
        )
    finally:
        if view.poll() is None:
            view.kill()
        view.wait(timeout=10)
        view_lines.close()
        end_processes(processes)
    # The observer with its certificate saw the run the batch engine computes.
    observed = read_recording(record).arrays()
    reference = simulate_batch(Scenario(fish=2, duration=5, seed=4))
    np.testing.assert_array_equal(observed["pos"], reference.position)


@pytest.mark.slow
def test_sigterm_stops_each_actor_as_ctrl_c_does_and_keeps_the_worlds_recording(
    tmp_path: Path,
) -> None:
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    record = tmp_path / "world.mcap"
    with started_commands() as start:
        router = start("router", "--listen", endpoint)
        wait_for_port(port)
        fish = start("fish", "--id", "0", "--id", "1", "--connect", endpoint)
        world = start("world", "--connect", endpoint, "--fish", "2", "--duration", "600",
                      "--period", "0.2", "--time", "realtime", "--record", str(record))  # fmt: skip
        lines = Lines(world)
        lines.wait_for(r"tick +0/", timeout=60)
        time.sleep(1.5)  # about seven ticks of 0.2 s in real time
        world.send_signal(signal.SIGTERM)
        assert world.wait(timeout=15) == 130, lines.seen
        lines.wait_for(rf"^recording: {re.escape(str(record))}$", timeout=5)
        lines.close()
        assert world.stdout is not None
        world.stdout.close()
        for process in (fish, router):
            process.send_signal(signal.SIGTERM)
            _, errors = process.communicate(timeout=15)
            assert process.returncode == 130, (process.args, errors)
    recording = read_recording(record)
    assert recording.complete and len(recording.snapshots) >= 5


@pytest.mark.slow
def test_a_world_says_when_it_loses_its_router_and_when_the_router_is_back() -> None:
    """The router dies in mid-run (a real-time run): the world says so at once, rather than
    only losing its fish one by one; a router back on the same address is said too. An
    observer of the run ends, exit 1, saying it lost the router before the run ended (the
    world's token went with the router, which is no end of the run)."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    with started_commands() as start:
        router = start("router", "--listen", endpoint)
        wait_for_port(port)
        start("fish", "--id", "0", "--connect", endpoint)
        world = start("world", "--connect", endpoint, "--fish", "1", "--duration", "600",
                      "--period", "0.2", "--time", "realtime", "--quiet")  # fmt: skip
        lines = Lines(world)
        lines.wait_for("world up on ", timeout=60)
        observer = start("observe", "--connect", endpoint)
        watched = Lines(observer)
        watched.wait_for("^observing swarm 'default'", timeout=30)
        time.sleep(1.0)  # a few snapshots observed
        router.kill()
        router.wait(timeout=10)
        lines.wait_for(
            rf"^fishswarm world: lost the router at {re.escape(endpoint)}: the swarm is out of "
            r"reach until it is back \(Ctrl-C to stop\)$",
            timeout=10,
        )
        # The observer saw the world's token go with the router: not the run's end.
        assert observer.wait(timeout=15) == 1, watched.seen
        watched.wait_for(
            rf"fishswarm observe: lost the router at {re.escape(endpoint)} before the run ended",
            timeout=5,
        )
        watched.close()
        start("router", "--listen", endpoint)
        lines.wait_for(
            rf"^fishswarm world: the router at {re.escape(endpoint)} is back$", timeout=30
        )
        world.send_signal(signal.SIGTERM)
        assert world.wait(timeout=15) == 130


@pytest.mark.slow
def test_an_observer_of_a_run_that_ends_does_not_say_it_lost_the_router(tmp_path: Path) -> None:
    """`fishswarm run` is the router too: at the run's end it goes, while the observer
    still waits for the run's last snapshots. That is the run ending, not a lost router
    (the observer said so at the end of every run before)."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    with started_commands() as start:
        run = start("run", "--fish", "2", "--duration", "3", "--time", "realtime",
                    "--period", "0.5", "--quiet", "--listen", endpoint,
                    "--record", str(tmp_path / "run.mcap"),
                    "--summary", str(tmp_path / "run.json"))  # fmt: skip
        wait_for_port(port)
        observed = tmp_path / "observed.mcap"
        observer = start("observe", "--connect", endpoint, "--record", str(observed))
        _, said = observer.communicate(timeout=60)
        assert observer.returncode == 0, said
        assert "observed ticks" in said and "lost the router" not in said, said
        assert run.wait(timeout=30) == 0
    # The observer's recording says what ran, as the run's own does (it said nothing).
    assert read_recording(observed).scenario == read_recording(tmp_path / "run.mcap").scenario


@pytest.mark.slow
def test_a_second_world_on_the_swarm_waits_for_the_first_and_records_only_its_own_run(
    tmp_path: Path,
) -> None:
    first_record, second_record = tmp_path / "first.mcap", tmp_path / "second.mcap"
    with routed_commands() as (endpoint, start):

        def world(*args: str) -> list[str]:
            return ["world", "--connect", endpoint, "--fish", "2", *args]

        start("fish", "--id", "0", "--id", "1", "--school", "pair", "--connect", endpoint)
        # The first world in real time, 30 s: the second comes while it runs.
        first = start(
            *world("--time", "realtime", "--duration", "30", "--record", str(first_record))
        )
        first_lines = Lines(first)
        first_lines.wait_for(r"tick +0/30")
        second = start(*world("--quiet", "--duration", "3", "--record", str(second_record)))
        said = Lines(second)
        said.wait_for("another world runs swarm 'default' on this router: waiting")
        # An operator's requests reach the world that runs, not the one waiting its turn.
        for action, state in (("status", "running"), ("status", "running"), ("stop", "stopping")):
            asked = subprocess.run(
                [*FISHSWARM, "control", action, "--connect", endpoint],
                capture_output=True, text=True, timeout=60, check=False,
            )  # fmt: skip
            assert asked.returncode == 0, asked.stderr
            assert asked.stdout.startswith(f"swarm 'default': {state} at tick "), asked.stdout
        assert first.wait(timeout=30) == 0
        first_lines.wait_for(r"^status: stopped at tick \d+ ")
        statistics = json.loads(said.wait_for(r"^\{.*\}$")[0])
        assert second.wait(timeout=30) == 0
    # The second counted none of the first run's commands as its own stale ones.
    assert statistics["ticks"] == 3 and statistics["rejected"] == {}
    own = read_recording(second_record)
    assert [s.tick for s in own.snapshots] == [0, 1, 2, 3]
    assert len({s.run for s in own.snapshots}) == 1
    theirs = read_recording(first_record)
    assert {s.run for s in theirs.snapshots}.isdisjoint({s.run for s in own.snapshots})


def test_a_world_names_the_parameters_a_fish_was_started_with_otherwise() -> None:
    """A formation of three: fish 2 was started with another spacing than the world's file
    says. Over real sessions, the world names it and the parameters that differ, and counts
    it; the run goes on to its end."""
    with routed_commands() as (endpoint, start):
        start("fish", "--id", "0", "--id", "1", "--school", "a", "--connect", endpoint,
              "--behavior", "formation", "--fish", "3")  # fmt: skip
        start("fish", "--id", "2", "--connect", endpoint, "--behavior", "formation",
              "--fish", "3", "--spacing", "0.25")  # fmt: skip
        world = subprocess.run(
            [*FISHSWARM, "world", "--connect", endpoint, "--fish", "3", "--behavior",
             "formation", "--duration", "3", "--start-timeout", "60"],
            capture_output=True, text=True, timeout=120, check=False,
        )  # fmt: skip
    assert world.returncode == 0, world.stderr
    assert (
        "fishswarm world: warning: fish 2 decide with other formation parameters than this "
        "world's scenario (their spacing and tolerance differ; a formation's map is made for "
        "--fish fish: give them the world's --config, --fish included) (started with other "
        "settings?)"
    ) in world.stderr.splitlines()
    assert json.loads(world.stderr.strip().splitlines()[-1])["mismatched_fish"] == 1


@pytest.mark.slow
def test_a_standalone_world_that_lost_a_fish_ends_degraded_as_a_run_does() -> None:
    with routed_commands() as (endpoint, start):
        start("fish", "--id", "0", "--connect", endpoint)
        doomed = start("fish", "--id", "1", "--connect", endpoint)
        world = start("world", "--connect", endpoint, "--fish", "2", "--time", "realtime",
                      "--duration", "6")  # fmt: skip
        said = Lines(world)
        said.wait_for(r"tick +1/6")
        doomed.kill()
        assert world.wait(timeout=60) == 4
        said.wait_for(r"^status: degraded at tick 6 \(6 s simulated, .*; 1 fish lost, ")
        said.wait_for(r"^fish were lost on the way: 1 at tick \d+ \(")
    statistics = json.loads(said.wait_for(r"^\{.*\}$")[0])
    assert statistics["lost_fish"] == 1 and statistics["ticks"] == 6


@pytest.mark.slow
def test_two_worlds_started_together_before_their_fish_both_run_one_after_the_other(
    tmp_path: Path,
) -> None:
    """Two worlds of a swarm, both up and waiting when the fish come: one runs, then the
    other (they used to wait for each other until both start timeouts ran out)."""
    records = [tmp_path / "a.mcap", tmp_path / "b.mcap"]
    timing = [("--duration", "3"), ("--duration", "1.5", "--period", "0.5")]
    with routed_commands() as (endpoint, start):
        worlds = [
            start(
                "world",
                "--connect",
                endpoint,
                "--fish",
                "2",
                *run_timing,
                "--quiet",
                "--start-timeout",
                "40",
                "--record",
                str(record),
            )
            for record, run_timing in zip(records, timing, strict=True)
        ]
        lines = [Lines(world) for world in worlds]
        for said in lines:
            said.wait_for(rf"^world up on {re.escape(endpoint)} for swarm 'default': the run "
                          r"starts when its 2 fish are up, after any world of the swarm that runs "
                          r"or came up first$", timeout=60)  # fmt: skip
        start("fish", "--id", "0", "--id", "1", "--connect", endpoint)
        for world, said, simulated in zip(worlds, lines, ("3", "1.5"), strict=True):
            assert world.wait(timeout=60) == 0, said.seen
            said.wait_for(
                rf"^status: finished at tick 3 \({re.escape(simulated)} s simulated, "
                r"\d+\.\d s wall time\); 0 fish lost, 0 messages rejected by the world$"
            )
    runs = [read_recording(record) for record in records]
    assert [[s.tick for s in run.snapshots] for run in runs] == [[0, 1, 2, 3]] * 2
    assert all(run.complete for run in runs)
    assert len({s.run for run in runs for s in run.snapshots}) == 2


@pytest.mark.slow
def test_a_standalone_channel_takes_each_runs_loss_and_seed_from_its_world(
    tmp_path: Path,
) -> None:
    """README's multi-machine recipe with a channel started on other settings (no loss,
    seed 9) than the world's (loss 0.5, seed 3): the channel takes the world's, so the run
    is the batch engine's run of the world's scenario, bit for bit. With the channel's own
    settings the fish would hear other flags (up to 0.37 m apart by the end)."""
    import numpy as np

    from fishswarm.sim.engine import simulate_batch
    from fishswarm.sim.scenario import Scenario

    world_config = tmp_path / "world.toml"
    world_config.write_text(
        '[scenario]\nfish = 6\nbehavior = "formation"\nduration = 20\nseed = 3\n'
        "channel_loss = 0.5\n"
    )
    channel_config = tmp_path / "channel.toml"
    channel_config.write_text("[scenario]\nchannel_loss = 0.0\nseed = 9\n")
    record = tmp_path / "world.mcap"
    with routed_commands() as (endpoint, start):
        channel = start(
            "--log-level", "INFO", "channel", "--connect", endpoint, "--config", str(channel_config)
        )
        channel_lines = Lines(channel)
        channel_lines.wait_for(r"^channel up on tcp/127\.0\.0\.1:\d+ for swarm 'default'")
        start("fish", "--connect", endpoint, "--config", str(world_config), "--school", "all",
              *[part for fish in range(6) for part in ("--id", str(fish))])  # fmt: skip
        world = subprocess.run(
            [*FISHSWARM, "world", "--connect", endpoint, "--config", str(world_config),
             "--start-timeout", "60", "--quiet", "--record", str(record)],
            capture_output=True, text=True, timeout=180, check=False,
        )  # fmt: skip
        assert world.returncode == 0, world.stderr
        statistics = json.loads(world.stderr.strip().splitlines()[-1])
        assert statistics["ticks"] == 20 and statistics["lost_fish"] == 0
        assert statistics["rejected"] == {} and statistics["mismatched_fish"] == 0
        channel_lines.wait_for(
            "channel: a run starts: range 3 m, loss 0.5, seed 3, flags by channel$", timeout=10
        )
        # Stopped, the channel says what it did: the world counted no rejection, nor it.
        channel.send_signal(signal.SIGTERM)
        assert channel.wait(timeout=15) == 130
        done = channel_lines.wait_for(
            r"^channel: (\d+) deliveries made, 0 broadcasts announced but missing, "
            r"0 broadcasts not delivered \(sent with a late or lost command\), "
            r"0 messages rejected by the channel$"
        )
        assert int(done.group(1)) > 0
    reference = simulate_batch(
        Scenario(fish=6, behavior="formation", duration=20.0, seed=3, channel_loss=0.5)
    )
    recorded = read_recording(record).arrays()
    np.testing.assert_array_equal(recorded["pos"], reference.position)
    np.testing.assert_array_equal(recorded["yaw"], reference.yaw)


def test_a_second_process_for_a_school_or_fish_already_served_is_refused() -> None:
    # Two 'fishswarm fish' given one --school: the world would send one batch for both,
    # which each refuses as not all its own, and lose every fish of the school.
    with routed_commands() as (endpoint, start):
        first = start("fish", "--id", "0", "--id", "1", "--school", "a", "--connect", endpoint)
        Lines(first).wait_for(r"^fish 0, 1 up on ")  # read on until the process ends

        def second(*options: str) -> subprocess.CompletedProcess[str]:
            command = ["fish", *options, "--connect", endpoint]
            return subprocess.run([*FISHSWARM, *command], capture_output=True, text=True,
                                  timeout=30, check=False)  # fmt: skip

        refused = second("--id", "2", "--school", "a")
        assert refused.returncode == 2
        assert (
            "fishswarm fish: error: school 'a' is served already, by another process with "
            "fish 0, 1: give each 'fishswarm fish' process its own --school"
        ) in refused.stderr
        # One of its fish, on its own keys: both would answer for it.
        twice = second("--id", "1", "--id", "5")
        assert twice.returncode == 2
        assert "fishswarm fish: error: fish 1 served already, by another process" in twice.stderr
        assert first.poll() is None  # the school's own process serves on
        other = start("fish", "--id", "2", "--school", "b", "--connect", endpoint)
        Lines(other).wait_for(r"^fish 2 up on ")
