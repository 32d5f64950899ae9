"""``fishswarm view``: a recording replayed and a running swarm followed in the browser, as
separate processes on 127.0.0.1, looked at by a real browser."""

from __future__ import annotations

import re
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from tests.cli.browser import browser_missing, fish_pixels, open_page, screenshot, wait_for_fish
from tests.cli.processes import started_commands
from tests.conftest import Lines, end_processes, free_port, wait_for_port

pytestmark = pytest.mark.integration

FISHSWARM = [sys.executable, "-m", "fishswarm"]


def _view(*args: str) -> tuple[subprocess.Popen[str], Lines]:
    process = subprocess.Popen(
        [*FISHSWARM, "view", *args, "--web-port", str(free_port()), "--grpc-port",
         str(free_port())],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    return process, Lines(process)


def _close(process: subprocess.Popen[str], lines: Lines) -> None:
    """Ctrl-C, as a person ends a view: it says so and exits 0."""
    process.send_signal(signal.SIGINT)
    assert process.wait(timeout=30) == 0
    lines.wait_for("fishswarm view: closed", timeout=10)


def _assert_fish_move(page_url: str, tmp_path: Path) -> None:
    """The page shows ten fish of a few hundred pixels each, and 5 s later (five ticks in
    real time) not in the same places."""
    with open_page(page_url) as page:
        wait_for_fish(page, tmp_path / "loading.png")
        before = fish_pixels(screenshot(page, tmp_path / "before.png"))
        time.sleep(5.0)
        after = fish_pixels(screenshot(page, tmp_path / "after.png"))
    assert before.sum() > 500 and after.sum() > 500
    moved = np.logical_xor(before, after).sum()
    assert moved > 0.2 * min(before.sum(), after.sum()), (moved, before.sum(), after.sum())


def _stop(process: subprocess.Popen[str], lines: Lines) -> None:
    process.kill()
    process.wait(timeout=10)
    lines.close()


@pytest.mark.parametrize(
    ("args", "code", "message"),
    [
        (["--web-port", "0"], 2, "--web-port must be a port number 1–65535, got 0"),
        (["--grpc-port", "99999"], 2, "--grpc-port must be a port number 1–65535, got 99999"),
        (["--web-port", "9300", "--grpc-port", "9300"], 2, "need two ports, got 9300"),
        (["missing.mcap"], 1, "cannot open recording missing.mcap"),
        (["--host", ""], 2, "--host '' is neither an IP address nor a host name"),
        (["--host", "bad host/x"], 2, "--host 'bad host/x' is neither an IP address nor"),
    ],
)
def test_bad_view_arguments_are_explained(args: list[str], code: int, message: str) -> None:
    done = subprocess.run(
        [*FISHSWARM, "view", *args], capture_output=True, text=True, timeout=60, check=False
    )
    assert done.returncode == code and message in done.stderr


def test_a_view_on_a_taken_port_says_so(tmp_path: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        done = subprocess.run(
            [*FISHSWARM, "view", "--web-port", str(port), "--grpc-port", str(free_port())],
            capture_output=True, text=True, timeout=60, check=False,
        )  # fmt: skip
    assert done.returncode == 1
    assert f"port {port} for the view's page is taken" in done.stderr
    assert "choose another with --web-port" in done.stderr


def test_a_recording_is_replayed_on_a_page_served_from_this_machine(tmp_path: Path) -> None:
    record = tmp_path / "run.mcap"
    ran = subprocess.run(
        [*FISHSWARM, "run", "--fish", "5", "--duration", "4", "--quiet", "--record",
         str(record), "--listen", f"tcp/127.0.0.1:{free_port()}"],
        capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert ran.returncode == 0, ran.stderr
    process, lines = _view(str(record))
    try:
        lines.wait_for(r"replaying .*run\.mcap: 5 snapshots, t = 0–4 s$")
        page = lines.wait_for(r"^open (http://localhost:(\d+)/\?url=(\S+)) in a browser")
        stream = re.fullmatch(r"rerun%2Bhttp%3A%2F%2Flocalhost%3A(\d+)%2Fproxy", page[3])
        assert stream is not None
        wait_for_port(int(stream[1]))
        with urllib.request.urlopen(page[1], timeout=10) as answer:
            assert answer.status == 200 and b"rerun" in answer.read().lower()
        _close(process, lines)
    finally:
        _stop(process, lines)


@pytest.mark.slow
@pytest.mark.skipif(browser_missing() is not None, reason=str(browser_missing()))
def test_the_live_view_shows_the_fish_moving_in_a_real_browser(tmp_path: Path) -> None:
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    run = subprocess.Popen(
        [*FISHSWARM, "run", "--behavior", "formation", "--fish", "10", "--time", "realtime",
         "--duration", "120", "--quiet", "--listen", endpoint],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, text=True,
    )  # fmt: skip
    process, lines = _view("--connect", endpoint)
    try:
        lines.wait_for(r"following swarm 'default' on tcp/127\.0\.0\.1:\d+$")
        page_url = lines.wait_for(r"^open (\S+) in a browser")[1]
        lines.wait_for(r"the world runs 10 fish, formation, 120 s")
        _assert_fish_move(page_url, tmp_path)
        _close(process, lines)
    finally:
        _stop(process, lines)
        run.kill()
        run.wait(timeout=10)


@pytest.mark.slow
@pytest.mark.skipif(browser_missing() is not None, reason=str(browser_missing()))
def test_a_view_left_up_follows_the_swarms_next_run_in_a_real_browser(tmp_path: Path) -> None:
    """README's standing swarm (router and fish stay up, worlds come and go) watched by one
    view: the first run (30 s, done in a moment) ends; the second, in real time, is shown
    as a new recording from its tick 0, and its fish move on the page. (An observer that
    took the second run for the first would refuse its snapshots until tick 31.)"""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    process, lines = _view("--connect", endpoint)
    try:
        with started_commands(piped=False) as start:
            start("router", "--listen", endpoint)
            wait_for_port(port)
            lines.wait_for(r"following swarm 'default' on tcp/127\.0\.0\.1:\d+$")
            page_url = lines.wait_for(r"^open (\S+) in a browser")[1]
            start("fish", "--connect", endpoint, "--school", "all",
                  *[part for fish in range(10) for part in ("--id", str(fish))])  # fmt: skip
            first = subprocess.run(
                [*FISHSWARM, "world", "--connect", endpoint, "--fish", "10", "--duration", "30",
                 "--start-timeout", "60", "--quiet"],
                capture_output=True, text=True, timeout=120, check=False,
            )  # fmt: skip
            assert first.returncode == 0, first.stderr
            lines.wait_for(r"the run has ended \(31 snapshots shown\)")
            start("world", "--connect", endpoint, "--fish", "10", "--duration", "120", "--time",
                  "realtime", "--start-timeout", "60", "--quiet")  # fmt: skip
            lines.wait_for(r"run 2 of swarm 'default' begins: shown as a new recording")
            lines.wait_for(r"the world runs 10 fish, dispersion, 120 s")
            _assert_fish_move(page_url, tmp_path)
            _close(process, lines)
    finally:
        _stop(process, lines)


@pytest.mark.slow
def test_a_view_left_up_tells_the_end_of_each_run_it_follows() -> None:
    """Two runs one after the other on a standing swarm, watched by one view (no browser):
    it says once when each ends, with the snapshots it showed of that run."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    processes: list[subprocess.Popen[str]] = []
    process, lines = _view("--connect", endpoint)
    try:
        processes.append(
            subprocess.Popen(
                [*FISHSWARM, "router", "--listen", endpoint],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, text=True,
            )
        )  # fmt: skip
        wait_for_port(port)
        lines.wait_for(r"following swarm 'default' on tcp/127\.0\.0\.1:\d+$")
        processes.append(
            subprocess.Popen(
                [*FISHSWARM, "fish", "--connect", endpoint, "--school", "all", "--id", "0",
                 "--id", "1", "--id", "2"],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, text=True,
            )
        )  # fmt: skip
        for duration, shown in ((8, 9), (5, 6)):
            world = subprocess.run(
                [*FISHSWARM, "world", "--connect", endpoint, "--fish", "3", "--duration",
                 str(duration), "--start-timeout", "60", "--quiet"],
                capture_output=True, text=True, timeout=120, check=False,
            )  # fmt: skip
            assert world.returncode == 0, world.stderr
            lines.wait_for(rf"the run has ended \({shown} snapshots shown\)")
        time.sleep(2.5)  # past the view's 1-s settle: an end said once is not said again
        _close(process, lines)
        ends = [line for line in lines.seen if "the run has ended" in line]
        assert [re.findall(r"\((\d+) snapshots shown\)", line) for line in ends] == [
            ["9"], ["6"],
        ]  # fmt: skip
        # In the order they happen: run 1 ends, then run 2 begins (and ends).
        order = [line for line in lines.seen if "the run has ended" in line or "begins" in line]
        assert [line.split(":")[1].split("(")[0].strip() for line in order] == [
            "the run has ended",
            "run 2 of swarm 'default' begins",
            "the run has ended",
        ]
        # Run 2 took 5 ticks in lockstep: a few ms, maybe over before the view asked its world.
        assert any(
            "the world runs 3 fish, dispersion, 5 s" in line or "run 2 ended before" in line
            for line in lines.seen
        )
        assert not any("waiting for the world" in line for line in lines.seen[3:]), lines.seen
    finally:
        _stop(process, lines)
        end_processes(processes)


@pytest.mark.slow
def test_a_view_with_no_world_to_follow_says_once_that_it_waits_for_one() -> None:
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    router = subprocess.Popen(
        [*FISHSWARM, "router", "--listen", endpoint],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, text=True,
    )  # fmt: skip
    process, lines = _view("--connect", endpoint, "--swarm", "tank2")
    try:
        wait_for_port(port)
        lines.wait_for(r"following swarm 'tank2' on tcp/127\.0\.0\.1:\d+$")
        lines.wait_for(
            rf"^fishswarm view: waiting for the world of swarm 'tank2' on {endpoint} "
            r"\(is a run going, and under this --swarm\?\)$"
        )
        time.sleep(5.0)  # more than two more unanswered asks
        _close(process, lines)
        assert sum("waiting for the world" in line for line in lines.seen) == 1, lines.seen
    finally:
        _stop(process, lines)
        end_processes([router])


@pytest.mark.parametrize("signal_number", [signal.SIGINT, signal.SIGTERM])
def test_a_ctrl_c_at_once_after_the_run_keeps_the_runs_exit_code(
    tmp_path: Path, signal_number: int
) -> None:
    # A script that stops the view as soon as it is told it may: the run's code, not 130.
    process = subprocess.Popen(
        [*FISHSWARM, "run", "--fish", "3", "--duration", "2", "--quiet", "--view",
         "--web-port", str(free_port()), "--grpc-port", str(free_port()),
         "--record", str(tmp_path / "r.mcap"), "--summary", str(tmp_path / "r.json"),
         "--listen", f"tcp/127.0.0.1:{free_port()}"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert process.stderr is not None
    try:
        # Read here, not through a reader thread: the signal goes out within microseconds of
        # the line, as a script's would (the race this test is for lay there).
        for line in iter(process.stderr.readline, ""):
            if "the view stays up until Ctrl-C" in line:
                process.send_signal(signal_number)
                break
        assert process.wait(timeout=30) == 0
    finally:
        if process.poll() is None:
            process.kill()
        process.communicate(timeout=30)


def test_a_run_serves_its_own_view_and_keeps_it_up_after_the_run(tmp_path: Path) -> None:
    web, grpc = free_port(), free_port()
    process = subprocess.Popen(
        [*FISHSWARM, "run", "--fish", "5", "--duration", "3", "--quiet", "--view",
         "--web-port", str(web), "--grpc-port", str(grpc), "--record", str(tmp_path / "r.mcap"),
         "--summary", str(tmp_path / "r.json"), "--listen", f"tcp/127.0.0.1:{free_port()}"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    lines = Lines(process)
    try:
        url = lines.wait_for(rf"^open (http://localhost:{web}/\S+) in a browser to watch$")[1]
        lines.wait_for("^status: finished$")
        lines.wait_for("the view stays up until Ctrl-C")
        with urllib.request.urlopen(url, timeout=10) as answer:
            assert answer.status == 200
        wait_for_port(grpc)
        process.send_signal(signal.SIGINT)
        assert process.wait(timeout=30) == 0  # the run's own exit code
    finally:
        _stop(process, lines)


def test_a_ctrl_c_that_interrupts_a_run_with_a_view_ends_the_view_too(tmp_path: Path) -> None:
    # The view stays up after a run that ended; one whose run was interrupted went on
    # serving until a second Ctrl-C.
    web, grpc = free_port(), free_port()
    process = subprocess.Popen(
        [*FISHSWARM, "run", "--fish", "3", "--duration", "600", "--time", "realtime",
         "--quiet", "--view", "--web-port", str(web), "--grpc-port", str(grpc),
         "--record", str(tmp_path / "r.mcap"), "--summary", str(tmp_path / "r.json"),
         "--listen", f"tcp/127.0.0.1:{free_port()}"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    lines = Lines(process)
    try:
        lines.wait_for(rf"^open (http://localhost:{web}/\S+) in a browser to watch$")
        wait_for_port(grpc)
        time.sleep(1.0)  # a few ticks
        process.send_signal(signal.SIGINT)
        lines.wait_for("fishswarm run: interrupted; recording and summary hold the run so far")
        assert process.wait(timeout=30) == 130  # it stayed up, serving the view
    finally:
        _stop(process, lines)


@pytest.mark.slow
def test_a_view_that_loses_its_router_says_so_and_says_when_the_world_is_back() -> None:
    # The router killed at about tick 3 of a real-time run: the view said "the run has
    # ended" while the world went on once the router was back.
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    process, lines = _view("--connect", endpoint)
    try:
        with started_commands(piped=False) as start:
            router = start("router", "--listen", endpoint)
            wait_for_port(port)
            lines.wait_for(r"following swarm 'default' on tcp/127\.0\.0\.1:\d+$")
            start("fish", "--connect", endpoint, "--id", "0", "--id", "1", "--school", "s")
            start("world", "--connect", endpoint, "--fish", "2", "--duration", "60", "--time",
                  "realtime", "--start-timeout", "60", "--quiet")  # fmt: skip
            lines.wait_for(r"the world runs 2 fish, dispersion, 60 s", timeout=60)
            time.sleep(3)
            router.kill()
            router.wait(timeout=10)
            said = lines.wait_for(r"(lost the router at .*|the run has ended.*)$", timeout=60)[1]
            assert said.startswith(f"lost the router at {endpoint} before the run ended"), said
            assert "its world never said the run was over" in said
            # A router back on the same address brings the world back, and the view says so
            # (it said nothing, and showed the run again under "lost the router").
            start("router", "--listen", endpoint)
            back = lines.wait_for(
                r"the world of run 1 is back \(the last snapshot shown was of tick (\d+)\): "
                r"the view goes on with it$",
                timeout=60,
            )
            assert int(back[1]) >= 2, back
            _close(process, lines)
    finally:
        end_processes([process])


@pytest.mark.slow
def test_a_view_without_the_runs_behaviour_installed_shows_the_run_all_the_same(
    tmp_path: Path,
) -> None:
    # The world runs another package's behaviour, not installed where the view runs: the
    # view failed with "error: the world's run has the behaviour ...", exit 2.
    import os

    from tests.behaviors.example_plugin import EXAMPLE, NEAREST_ENTRY_POINT, installed

    site = tmp_path / "site"
    installed(site, "fishswarm-nearest", NEAREST_ENTRY_POINT)
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    process, lines = _view("--connect", endpoint)
    run = subprocess.Popen(
        [*FISHSWARM, "run", "--behavior", "nearest", "--fish", "3", "--duration", "4",
         "--time", "realtime", "--quiet", "--listen", endpoint,
         "--record", str(tmp_path / "r.mcap"), "--summary", str(tmp_path / "r.json")],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, text=True,
        env={**os.environ, "PYTHONPATH": f"{site}{os.pathsep}{EXAMPLE}"},
    )  # fmt: skip
    try:
        said = lines.wait_for(
            r"warning: the world's run has the behaviour 'nearest'.*$", timeout=60
        )
        assert said[0].endswith("; the view shows run 1 without its settings"), said[0]
        lines.wait_for(r"the run has ended \(([2-9]|\d\d+) snapshots shown\)", timeout=60)
        assert run.wait(timeout=30) == 0
        _close(process, lines)
    finally:
        end_processes([process, run])
