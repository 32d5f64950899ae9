"""The shared test helpers themselves."""

from __future__ import annotations

import socket

from tests.conftest import free_port


def test_free_ports_differ_and_can_be_listened_on() -> None:
    ports = [free_port() for _ in range(40)]
    assert len(set(ports)) == len(ports)
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as server:
        server.bind(("127.0.0.1", ports[-1]))
        server.listen()
