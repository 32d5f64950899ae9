"""The Zenoh Bus and sessions over real sessions on 127.0.0.1, and the trio inbox."""

from __future__ import annotations

import contextlib
import queue
import signal
import threading
import time
from pathlib import Path

import pytest
import trio
import zenoh

from fishswarm.actors.bus import open_alive_events, open_token
from fishswarm.actors.inbox import Inbox
from fishswarm.actors.session import ConnectError, SessionSettings, check_endpoint, open_session
from fishswarm.actors.zenoh_bus import ZenohBus, open_queryable, query, reply
from tests.conftest import free_port, run_trio, subscription, wait_until_routed

pytestmark = pytest.mark.integration


def test_inbox_keeps_order_across_threads() -> None:
    async def main() -> list[int]:
        inbox: Inbox[int] = Inbox()

        def produce() -> None:
            for n in range(10_000):
                inbox.push(n)

        thread = threading.Thread(target=produce)
        thread.start()
        received = [await inbox.receive() for _ in range(10_000)]
        thread.join()
        return received

    assert run_trio(main) == list(range(10_000))


def test_inbox_receive_nowait_raises_would_block_when_empty() -> None:
    async def main() -> tuple[int, list[int]]:
        inbox: Inbox[int] = Inbox()
        with pytest.raises(trio.WouldBlock):
            inbox.receive_nowait()
        for n in (4, 5, 6):
            inbox.push(n)
        first = inbox.receive_nowait()
        return first, inbox.drain()

    assert run_trio(main) == (4, [5, 6])


def test_put_reaches_subscriber_through_router(endpoint: str) -> None:
    async def main() -> list[tuple[str, bytes]]:
        router = SessionSettings(mode="router", listen=[endpoint])
        client = SessionSettings(mode="client", connect=[endpoint])
        async with (
            open_session(router),
            open_session(client) as a,
            open_session(client) as b,
            subscription(ZenohBus(b), "test/**") as inbox,
        ):
            sender = ZenohBus(a)
            await wait_until_routed(sender, inbox, "test/probe")
            for n in range(3):
                sender.put(f"test/{n}", bytes([n]))
            got = [await inbox.receive() for _ in range(3)]
            return got

    assert run_trio(main) == [("test/0", b"\x00"), ("test/1", b"\x01"), ("test/2", b"\x02")]


@pytest.mark.parametrize("inline", [True, False])
def test_an_inline_subscriber_hears_its_own_session_inside_the_put(
    endpoint: str, inline: bool
) -> None:
    # Actors sharing a process (the launcher's fish beside its world) hand each other a
    # sample without a thread in between; by default each subscriber has a thread of its own.
    async def main() -> tuple[list[tuple[int, bytes]], bool]:
        async with open_session(SessionSettings(mode="router", listen=[endpoint])) as session:
            bus = ZenohBus(session, inline=inline)
            heard: list[tuple[int, bytes]] = []
            subscriber = bus.subscribe(
                "test/inline", lambda _, payload: heard.append((threading.get_ident(), payload))
            )
            try:
                bus.put("test/inline", b"one")
                inside = heard == [(threading.get_ident(), b"one")]
                with trio.fail_after(5):
                    while not heard:
                        await trio.sleep(0.01)
            finally:
                subscriber.undeclare()
            return heard, inside

    heard, inside = run_trio(main)
    assert [payload for _, payload in heard] == [b"one"]
    assert inside is inline
    assert (heard[0][0] == threading.get_ident()) is inline


def test_ctrl_c_inside_an_inline_callback_reaches_trio_and_the_sample_is_kept(
    endpoint: str,
) -> None:
    # Zenoh logs and drops whatever a callback raises; an inline callback runs in trio's
    # thread, where the signal may land, so the interrupt must wait for trio to deliver it.
    heard: list[bytes] = []

    def interrupted_while_hearing(_: str, payload: bytes) -> None:
        signal.raise_signal(signal.SIGINT)
        heard.append(payload)

    async def main() -> None:
        async with open_session(SessionSettings(mode="router", listen=[endpoint])) as session:
            bus = ZenohBus(session, inline=True)
            subscriber = bus.subscribe("test/interrupted", interrupted_while_hearing)
            try:
                bus.put("test/interrupted", b"kept")
                await trio.sleep(5)  # the interrupt ends this at the first checkpoint
            finally:
                subscriber.undeclare()

    started = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        trio.run(main)
    assert heard == [b"kept"]
    assert time.monotonic() - started < 4


def test_liveliness_tokens_come_and_go(endpoint: str) -> None:
    async def main() -> list[tuple[str, bool]]:
        router = SessionSettings(mode="router", listen=[endpoint])
        client = SessionSettings(mode="client", connect=[endpoint])
        events: Inbox[tuple[str, bool]] = Inbox()
        async with (
            open_session(router) as hub,
            open_alive_events(ZenohBus(hub), "alive/**", lambda k, a: events.push((k, a))),
        ):
            async with open_session(client) as member:
                async with open_token(ZenohBus(member), "alive/fish/7"):
                    first = await events.receive()
                second = await events.receive()
            return [first, second]

    assert run_trio(main) == [("alive/fish/7", True), ("alive/fish/7", False)]


def test_queryable_answers_from_trio_with_what_was_noted_as_the_query_came(
    endpoint: str,
) -> None:
    """A query comes with its note as it was on arrival: the flag changes right after, before
    trio takes the query in, and the answer still says what it was."""
    flag = [True]

    def noted() -> bool:
        answer = flag[0]
        flag[0] = False  # changed at once: trio sees the query only later
        return answer

    async def main() -> list[bytes]:
        router = SessionSettings(mode="router", listen=[endpoint])
        client = SessionSettings(mode="client", connect=[endpoint])
        async with (
            open_session(router) as hub,
            open_session(client) as asker,
            open_queryable(hub, "ctl", noted) as queries,
            trio.open_nursery() as nursery,
        ):

            async def serve() -> None:
                async for request, note in queries:
                    assert request.payload is not None
                    reply(request, b"pong:%s:%r" % (request.payload.to_bytes(), note))

            nursery.start_soon(serve)
            # The queryable may take a moment to reach the asker's router: ask until answered.
            with trio.fail_after(10):
                while not (answers := await query(asker, "ctl", b"ping", timeout=0.5)):
                    pass
            nursery.cancel_scope.cancel()
            return answers

    assert run_trio(main) == [b"pong:ping:True"]


def test_connecting_to_nothing_fails_clearly() -> None:
    settings = SessionSettings(
        mode="client", connect=[f"tcp/127.0.0.1:{free_port()}"], connect_timeout=0.5
    )

    async def main() -> None:
        async with open_session(settings):
            pass

    with pytest.raises(
        ConnectError, match="is a fishswarm run or router listening there"
    ) as raised:
        run_trio(main)
    # A plain client of a secured router fails the same way: the message says where to look.
    assert "a secured swarm's router listens on tls/" in str(raised.value)


def test_a_tls_client_that_cannot_open_is_told_to_check_its_certificates() -> None:
    """Zenoh gives the same timeout for a router that is not there and one that refuses the
    handshake (another authority, a key that is not the certificate's, a host the router's
    certificate does not name): the message names both."""
    settings = SessionSettings(
        mode="client", connect=[f"tls/127.0.0.1:{free_port()}"], connect_timeout=0.5
    )

    async def main() -> None:
        async with open_session(settings):
            pass

    with pytest.raises(ConnectError, match="does it accept this certificate") as raised:
        run_trio(main)
    assert "--secure must name a folder of the router's own authority" in str(raised.value)


def test_port_in_use_fails_clearly(endpoint: str) -> None:
    async def main() -> None:
        settings = SessionSettings(mode="router", listen=[endpoint])
        async with open_session(settings), open_session(settings):
            pass

    with pytest.raises(ConnectError, match="another program using that port"):
        run_trio(main)


def test_listening_on_an_address_not_of_this_machine_says_so(endpoint: str) -> None:
    # 192.0.2.1 is in TEST-NET-1 (RFC 5737), reserved for documentation: no machine
    # here has it, so binding to it fails with EADDRNOTAVAIL, not EADDRINUSE.
    port = endpoint.rpartition(":")[2]
    settings = SessionSettings(mode="router", listen=[f"tcp/192.0.2.1:{port}"])

    async def main() -> None:
        async with open_session(settings):
            pass

    with pytest.raises(ConnectError, match="this machine has no such address") as failure:
        run_trio(main)
    assert "another program" not in str(failure.value)


@pytest.mark.parametrize("bad", ["127.0.0.1:7447", "tcp/127.0.0.1", "tcp/:7447", "xyz/a:1"])
def test_bad_endpoints_are_explained(bad: str) -> None:
    with pytest.raises(ValueError, match="PROTOCOL/HOST:PORT"):
        check_endpoint(bad)


@pytest.mark.skipif(not Path("/dev/shm").is_dir(), reason="no /dev/shm on this machine")
@pytest.mark.parametrize(("pool", "shared"), [(4 * 2**20, True), (256 * 2**10, False)])
def test_large_messages_go_through_shared_memory_when_the_pool_holds_them(
    endpoint: str, pool: int, shared: bool
) -> None:
    # 1 MiB messages from the router to a client on this machine: copied into the
    # router's shared-memory pool when the pool can hold them, through the socket when not;
    # the same bytes arrive either way. (The pool is made when the session opens, not at
    # the first large message as Zenoh does by default, so no message goes ahead of it.)
    body = bytes(range(256)) * 4096
    router = SessionSettings(
        mode="router",
        listen=[endpoint],
        shared_memory_pool_bytes=pool,
        extra={"transport/shared_memory/mode": "init"},
    )
    client = SessionSettings(mode="client", connect=[endpoint])
    arrived: queue.Queue[tuple[bytes, bool]] = queue.Queue()

    def on_sample(sample: zenoh.Sample) -> None:
        arrived.put((sample.payload.to_bytes(), sample.payload.as_shm() is not None))

    def next_numbered(number: int) -> tuple[bytes, bool]:
        while True:  # skip any earlier message still on its way
            payload, through_shared_memory = arrived.get(timeout=5)
            if payload[:8] == number.to_bytes(8, "little"):
                return payload[8:], through_shared_memory

    with zenoh.open(router.to_config()) as sender, zenoh.open(client.to_config()) as receiver:
        subscriber = receiver.declare_subscriber("test/large", on_sample)
        try:
            for _ in range(50):  # until the subscription has reached the router
                sender.put("test/large", (0).to_bytes(8, "little") + body)
                with contextlib.suppress(queue.Empty):
                    arrived.get(timeout=0.1)
                    break
            # The other copies of message 0 still on their way hold room in the pool (on a
            # loaded machine, as many as it has): let them all arrive and be let go first.
            with contextlib.suppress(queue.Empty):
                while True:
                    arrived.get(timeout=0.5)
            later = []
            for number in (1, 2, 3):  # one at a time: the pool never holds more than one
                sender.put("test/large", number.to_bytes(8, "little") + body)
                later.append(next_numbered(number))
        finally:
            subscriber.undeclare()
    assert later == [(body, shared)] * 3


def test_a_shared_memory_pool_must_have_room() -> None:
    with pytest.raises(ValueError, match="positive number of bytes, got 0"):
        SessionSettings(mode="router", shared_memory_pool_bytes=0)
