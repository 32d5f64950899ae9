"""The Zenoh ↔ trio bridge over real sessions on 127.0.0.1."""

from __future__ import annotations

import threading

import pytest
import trio

from fishswarm.actors.bridge import (
    ConnectError,
    Inbox,
    SessionSettings,
    check_endpoint,
    open_liveliness_watch,
    open_queryable,
    open_session,
    open_subscription,
    open_token,
    publisher,
    query,
    reply,
)
from tests.conftest import free_port, run_trio

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


def test_put_reaches_subscriber_through_router(endpoint: str) -> None:
    async def main() -> list[tuple[str, bytes]]:
        router = SessionSettings(mode="router", listen=[endpoint])
        client = SessionSettings(mode="client", connect=[endpoint])
        async with (
            open_session(router) as hub,
            open_session(client) as a,
            open_session(client) as b,
            open_subscription(b, "test/**") as inbox,
        ):
            await trio.sleep(0.2)  # let the subscription propagate through the router
            put = publisher(a)
            for n in range(3):
                put(f"test/{n}", bytes([n]))
            got = [await inbox.receive() for _ in range(3)]
            assert hub is not None
            return got

    assert run_trio(main) == [("test/0", b"\x00"), ("test/1", b"\x01"), ("test/2", b"\x02")]


def test_liveliness_tokens_come_and_go(endpoint: str) -> None:
    async def main() -> list[tuple[str, bool]]:
        router = SessionSettings(mode="router", listen=[endpoint])
        client = SessionSettings(mode="client", connect=[endpoint])
        async with open_session(router) as hub, open_liveliness_watch(hub, "alive/**") as events:
            async with open_session(client) as member:
                async with open_token(member, "alive/fish/7"):
                    first = await events.receive()
                second = await events.receive()
            return [first, second]

    assert run_trio(main) == [("alive/fish/7", True), ("alive/fish/7", False)]


def test_queryable_answers_from_trio(endpoint: str) -> None:
    async def main() -> list[bytes]:
        router = SessionSettings(mode="router", listen=[endpoint])
        client = SessionSettings(mode="client", connect=[endpoint])
        async with (
            open_session(router) as hub,
            open_session(client) as asker,
            open_queryable(hub, "ctl") as queries,
            trio.open_nursery() as nursery,
        ):

            async def serve() -> None:
                request = await queries.receive()
                assert request.payload is not None
                reply(request, b"pong:" + request.payload.to_bytes())

            nursery.start_soon(serve)
            await trio.sleep(0.2)
            return await query(asker, "ctl", b"ping", timeout=5.0)

    assert run_trio(main) == [b"pong:ping"]


def test_connecting_to_nothing_fails_clearly() -> None:
    settings = SessionSettings(
        mode="client", connect=[f"tcp/127.0.0.1:{free_port()}"], connect_timeout=0.5
    )

    async def main() -> None:
        async with open_session(settings):
            pass

    with pytest.raises(ConnectError, match="is a fishswarm run or router listening there"):
        run_trio(main)


def test_port_in_use_fails_clearly(endpoint: str) -> None:
    async def main() -> None:
        settings = SessionSettings(mode="router", listen=[endpoint])
        async with open_session(settings), open_session(settings):
            pass

    with pytest.raises(ConnectError, match="another program using that port"):
        run_trio(main)


@pytest.mark.parametrize("bad", ["127.0.0.1:7447", "tcp/127.0.0.1", "tcp/:7447", "xyz/a:1"])
def test_bad_endpoints_are_explained(bad: str) -> None:
    with pytest.raises(ValueError, match="PROTOCOL/HOST:PORT"):
        check_endpoint(bad)
