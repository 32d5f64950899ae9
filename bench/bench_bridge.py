"""Benchmark: the floors under the fish round trip — Zenoh alone, and Zenoh plus the trio bridge.

Both echo a 200-byte payload from a spawned process over a router on 127.0.0.1 and are
timed from a plain Zenoh session (put from this thread, time-stamped in Zenoh's callback
thread), like the fish round trip in ``bench_swarm.py``:

- ``zenoh``: the echo process answers inside Zenoh's callback (a put from a callback is
  fine here because nothing else runs in that process; the actors never do it).
- ``trio bridge``: the echo process is a trio task reading an :class:`Inbox` and putting
  on a :class:`ZenohBus`, as every actor does.

Usage:
    python bench/bench_bridge.py [--samples 2000]
"""

from __future__ import annotations

import argparse
import multiprocessing
import threading
import time
from typing import Any

import numpy as np
import trio
import zenoh

from fishswarm.actors.bus import open_subscriber
from fishswarm.actors.inbox import Inbox
from fishswarm.actors.session import SessionSettings, free_loopback_endpoint, open_session
from fishswarm.actors.zenoh_bus import ZenohBus

PING, PONG = "bench/ping", "bench/pong"


def zenoh_echo(endpoint: str, extra: dict[str, Any] | None = None) -> None:
    """Echo in Zenoh's callback thread until killed (``extra``: further session settings,
    e.g. TLS)."""
    settings = SessionSettings(mode="client", connect=[endpoint], extra=extra or {})
    session = zenoh.open(settings.to_config())
    pong = session.declare_keyexpr(PONG)
    session.declare_subscriber(PING, lambda sample: session.put(pong, sample.payload))
    threading.Event().wait()


def trio_echo(endpoint: str) -> None:
    """Echo through the trio bridge until killed."""

    async def serve() -> None:
        async with open_session(SessionSettings(mode="client", connect=[endpoint])) as session:
            bus = ZenohBus(session)
            inbox: Inbox[bytes] = Inbox()
            async with open_subscriber(bus, PING, lambda _, payload: inbox.push(payload)):
                async for payload in inbox:
                    bus.put(PONG, payload)

    trio.run(serve)


def echo_round_trips(
    target: str,
    samples: int,
    *,
    endpoint: str | None = None,
    router_extra: dict[str, Any] | None = None,
    echo_extra: dict[str, Any] | None = None,
) -> np.ndarray:
    """Round trips in ms to an echo process running ``target`` (``zenoh`` or ``trio``),
    over a router on ``endpoint`` (default a free loopback TCP port) with further router
    and echo-session settings (e.g. TLS and access control; ``zenoh`` echo only)."""
    endpoint = endpoint or free_loopback_endpoint()
    router = SessionSettings(mode="router", listen=[endpoint], extra=router_extra or {})
    session = zenoh.open(router.to_config())
    arrived = threading.Event()
    stamp = [0.0]

    def on_pong(sample: zenoh.Sample) -> None:
        stamp[0] = time.perf_counter()
        arrived.set()

    subscriber = session.declare_subscriber(PONG, on_pong)
    arguments: tuple[Any, ...] = (endpoint, echo_extra) if target == "zenoh" else (endpoint,)
    main = zenoh_echo if target == "zenoh" else trio_echo
    process = multiprocessing.get_context("spawn").Process(target=main, args=arguments)
    process.start()
    times: list[float] = []
    try:
        time.sleep(2.0)
        ping = session.declare_keyexpr(PING)
        payload = bytes(200)
        for n in range(samples + 50):
            arrived.clear()
            started = time.perf_counter()
            session.put(ping, payload, congestion_control=zenoh.CongestionControl.BLOCK)
            if not arrived.wait(5.0):
                raise RuntimeError("no echo within 5 s")
            if n >= 50:
                times.append(stamp[0] - started)
    finally:
        process.kill()
        process.join()
        subscriber.undeclare()
        session.close()
    return np.array(times) * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--samples", type=int, default=2000, help="echo round trips timed (default 2000)"
    )
    args = parser.parse_args()
    for target in ("zenoh", "trio"):
        times = echo_round_trips(target, args.samples)
        print(
            f"echo through {target:5s}: p50 {np.percentile(times, 50):.3f} ms, "
            f"p90 {np.percentile(times, 90):.3f} ms, p99 {np.percentile(times, 99):.3f} ms"
        )


if __name__ == "__main__":
    main()
