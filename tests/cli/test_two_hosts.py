"""Fish workers on another host: two network namespaces joined by a veth pair stand for the
base station (router, world, channel) and a second machine (two school workers)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fishswarm.sim.engine import simulate_batch
from fishswarm.sim.scenario import Scenario
from fishswarm.study.recording import read_recording
from tests.conftest import end_processes, free_port

pytestmark = pytest.mark.integration

FISHSWARM = [sys.executable, "-m", "fishswarm"]


def _ip(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=10, check=False)


@pytest.fixture
def two_hosts() -> Iterator[tuple[str, str, str]]:
    """Namespaces (base, workers) and the base station's address; skipped where they cannot
    be made (not root, no iproute2)."""
    if os.geteuid() != 0:
        pytest.skip("network namespaces need root")
    tag = f"{os.getpid() % 100000}"
    base, workers = f"fsbase{tag}", f"fswork{tag}"
    made = _ip("netns", "add", base)
    if made.returncode != 0:
        pytest.skip(f"cannot create a network namespace: {made.stderr.strip()}")
    try:
        steps = [
            ("netns", "add", workers),
            ("link", "add", f"vb{tag}", "type", "veth", "peer", "name", f"vw{tag}"),
            ("link", "set", f"vb{tag}", "netns", base),
            ("link", "set", f"vw{tag}", "netns", workers),
            ("-n", base, "addr", "add", "10.201.0.1/24", "dev", f"vb{tag}"),
            ("-n", workers, "addr", "add", "10.201.0.2/24", "dev", f"vw{tag}"),
            ("-n", base, "link", "set", f"vb{tag}", "up"),
            ("-n", workers, "link", "set", f"vw{tag}", "up"),
            ("-n", base, "link", "set", "lo", "up"),
            ("-n", workers, "link", "set", "lo", "up"),
        ]
        for step in steps:
            done = _ip(*step)
            if done.returncode != 0:
                pytest.skip(f"cannot join the namespaces (ip {' '.join(step)}): {done.stderr}")
        yield base, workers, "10.201.0.1"
    finally:
        _ip("netns", "del", base)
        _ip("netns", "del", workers)


def _run_two_hosts(
    base: str, workers: str, address: str, record: Path, delay: float
) -> dict[str, Any]:
    """Router, world and channel in ``base``; two school workers of four fish each in
    ``workers``, reaching the router directly or through a relay that delays every byte by
    ``delay`` s each way. Returns the world's statistics."""
    port, relayed = free_port(), free_port()
    endpoint = f"tcp/{address}:{port}"
    processes: list[subprocess.Popen[str]] = []

    def start(namespace: str, *args: str) -> subprocess.Popen[str]:
        process = subprocess.Popen(
            ["ip", "netns", "exec", namespace, *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        processes.append(process)
        return process

    try:
        start(base, *FISHSWARM, "router", "--listen", endpoint)
        reach = endpoint
        if delay:
            relay = start(
                base,
                sys.executable,
                "-m",
                "tests.cli.delay_relay",
                f"{address}:{relayed}",
                f"{address}:{port}",
                str(delay),
            )
            assert relay.stdout is not None and relay.stdout.readline().strip() == "ready"
            reach = f"tcp/{address}:{relayed}"
        common = ("--connect-timeout", "20", "--behavior", "aggregation")
        for school, ids in (("w0", range(0, 4)), ("w1", range(4, 8))):
            start(workers, *FISHSWARM, "fish", "--connect", reach, *common, "--school", school,
                  *_ids(ids))  # fmt: skip
        start(base, *FISHSWARM, "channel", "--connect", endpoint, "--connect-timeout", "20")
        run = ("--fish", "8", "--duration", "6", "--seed", "6", "--record", str(record))
        world = subprocess.run(
            [
                "ip",
                "netns",
                "exec",
                base,
                *FISHSWARM,
                "world",
                "--connect",
                endpoint,
                *common,
                *run,
                "--quiet",
            ],
            capture_output=True,
            text=True,
            timeout=180,
            check=False,
        )
        assert world.returncode == 0, world.stderr
        statistics: dict[str, Any] = json.loads(world.stderr.strip().splitlines()[-1])
        return statistics
    finally:
        end_processes(processes)


@pytest.mark.slow
def test_workers_on_another_host_give_the_one_host_trajectory_on_fast_and_slow_links(
    two_hosts: tuple[str, str, str], tmp_path: Path
) -> None:
    # This kernel has no netem; a relay in the base station's namespace holds every byte
    # 40 ms each way on the second run instead: lockstep waits for it, the trajectory does
    # not change, and the world's answer times show the added 80 ms round trip.
    base, workers, address = two_hosts
    reference = simulate_batch(Scenario(fish=8, duration=6.0, seed=6, behavior="aggregation"))
    answers = []
    for delay in (0.0, 0.04):
        record = tmp_path / f"delay-{delay}.mcap"
        statistics = _run_two_hosts(base, workers, address, record, delay)
        assert statistics["ticks"] == 6 and statistics["lost_fish"] == 0
        assert statistics["rejected"] == {}
        recorded = read_recording(record).arrays()
        np.testing.assert_array_equal(recorded["ids"], reference.ids)
        np.testing.assert_array_equal(recorded["pos"], reference.position)
        np.testing.assert_array_equal(recorded["yaw"], reference.yaw)
        answers.append(statistics["answer_time_median"])
    fast, slow = answers
    assert 0 < fast < 0.05
    assert slow >= 0.08 and slow - fast > 0.06


def _ids(ids: range) -> list[str]:
    return [part for fish in ids for part in ("--id", str(fish))]
