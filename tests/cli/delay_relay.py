"""A TCP relay that holds every byte for a fixed delay each way: a slow link between two
hosts where the kernel has no netem (``python -m tests.cli.delay_relay LISTEN TARGET DELAY``,
addresses as HOST:PORT, the delay in seconds). Order is kept; nothing is dropped."""

from __future__ import annotations

import queue
import socket
import sys
import threading
import time


def _pump(source: socket.socket, target: socket.socket, delay: float) -> None:
    held: queue.Queue[tuple[float, bytes]] = queue.Queue()

    def send() -> None:
        while True:
            due, chunk = held.get()
            time.sleep(max(0.0, due - time.monotonic()))
            if not chunk:
                target.shutdown(socket.SHUT_WR)
                return
            target.sendall(chunk)

    threading.Thread(target=send, daemon=True).start()
    while True:
        try:
            chunk = source.recv(65536)
        except OSError:
            chunk = b""
        held.put((time.monotonic() + delay, chunk))
        if not chunk:
            return


def _connect(target: tuple[str, int], patience: float = 10.0) -> socket.socket | None:
    """A connection to ``target``, retried while it is not listening yet (None: never)."""
    give_up = time.monotonic() + patience
    while True:
        try:
            connection = socket.create_connection(target, timeout=patience)
            connection.settimeout(None)  # the link may idle: reads wait as long as it does
            return connection
        except OSError:
            if time.monotonic() > give_up:
                return None
            time.sleep(0.05)


def _address(text: str) -> tuple[str, int]:
    host, port = text.rsplit(":", 1)
    return host, int(port)


def main() -> None:
    listen, target, delay = _address(sys.argv[1]), _address(sys.argv[2]), float(sys.argv[3])
    server = socket.create_server(listen)
    print("ready", flush=True)
    while True:
        client, _ = server.accept()
        upstream = _connect(target)
        if upstream is None:
            client.close()
            continue
        for one, other in ((client, upstream), (upstream, client)):
            one.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            threading.Thread(target=_pump, args=(one, other, delay), daemon=True).start()


if __name__ == "__main__":
    main()
