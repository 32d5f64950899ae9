"""Benchmark: what securing a swarm costs — mutual TLS and access control against plain TCP.

In one run, on 127.0.0.1:

- the Zenoh echo round trip (``bench_bridge.py``: a 200-byte put answered from a spawned
  process) over a plain router, and over a router with mutual TLS and an access control that
  denies by default and allows the echo's certificate only its two keys;
- a 25-fish run (``fishswarm run``: dispersion, 30 s, one worker process), open and
  ``--secure`` (its worker on a certificate signed for the run, the router's access control
  extended for it): real-time factor and time per tick.

Usage:
    python bench/bench_security.py [--samples 2000] [--repeats 3]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import trio
from bench_bridge import PING, PONG, echo_round_trips

from fishswarm.actors.launcher import LaunchSettings, launch_swarm
from fishswarm.actors.security import init_secure, session_security
from fishswarm.actors.session import free_loopback_endpoint
from fishswarm.sim.scenario import Scenario


def echo_access(subject: str) -> dict[str, Any]:
    """Deny by default; ``subject`` may take pings and send pongs."""
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": [
            {"id": "ping", "messages": ["declare_subscriber", "put"],
             "flows": ["ingress", "egress"], "permission": "allow", "key_exprs": [PING]},
            {"id": "pong", "messages": ["put"], "flows": ["ingress"], "permission": "allow",
             "key_exprs": [PONG]},
        ],
        "subjects": [{"id": "echo", "cert_common_names": [subject]}],
        "policies": [{"rules": ["ping", "pong"], "subjects": ["echo"]}],
    }  # fmt: skip


def secure_echo(folder: Path, samples: int) -> np.ndarray:
    """Echo round trips, ms, over mutual TLS with access control."""
    router = session_security(folder, "router", router=True)
    router["access_control"] = echo_access("world")
    endpoint = free_loopback_endpoint().replace("tcp/", "tls/")
    return echo_round_trips(
        "zenoh", samples, endpoint=endpoint, router_extra=router,
        echo_extra=session_security(folder, "world"),
    )  # fmt: skip


def swarm(secure: Path | None) -> dict[str, float]:
    """One 25-fish run; real-time factor and ms per tick."""
    listen = free_loopback_endpoint()
    if secure is not None:
        listen = listen.replace("tcp/", "tls/")
    # One worker process: the tick's messages cross the secured link (fish in the launcher's
    # process would talk to the world inside it, where TLS has no part).
    settings = LaunchSettings(
        Scenario(fish=25, duration=30.0, seed=2), procs=1, listen=listen, secure=secure
    )
    summary = trio.run(lambda: launch_swarm(settings)).summary
    return {
        "real_time_factor": summary["real_time_factor"],
        "tick_ms": 1e3 * summary["loop_time"] / summary["counts"]["ticks"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--samples", type=int, default=2000, help="echo round trips timed (default 2000)"
    )
    parser.add_argument("--repeats", type=int, default=3, help="25-fish runs of each kind")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as text:
        folder = Path(text)
        init_secure(folder)
        plain = echo_round_trips("zenoh", args.samples)
        secured = secure_echo(folder, args.samples)
        print("| echo round trip | p50 (ms) | p90 (ms) | p99 (ms) |\n|---|---:|---:|---:|")
        for name, times in (("plain TCP", plain), ("mutual TLS + access control", secured)):
            p50, p90, p99 = np.percentile(times, [50, 90, 99])
            print(f"| {name} | {p50:.3f} | {p90:.3f} | {p99:.3f} |")
        ratio = np.percentile(secured, 50) / np.percentile(plain, 50)
        print(f"\nsecured / plain echo (p50): {ratio:.2f}\n")
        rows: dict[str, list[dict[str, float]]] = {"open": [], "secure": []}
        for _ in range(args.repeats):  # interleaved, so that drifts hit both alike
            rows["open"].append(swarm(None))
            rows["secure"].append(swarm(folder))
        print("| 25-fish run | real-time factor (median) | ms per tick (median) |")
        print("|---|---:|---:|")
        medians = {}
        for name, runs in rows.items():
            factor = float(np.median([r["real_time_factor"] for r in runs]))
            tick = float(np.median([r["tick_ms"] for r in runs]))
            medians[name] = tick
            print(f"| {name} | {factor:.0f}× | {tick:.2f} |")
        print(f"\nsecured / open tick: {medians['secure'] / medians['open']:.2f}")


if __name__ == "__main__":
    main()
