"""Where the live view is served: the page's and the data stream's ports and addresses.

Apart from :mod:`.live_view` so that the command line knows the defaults without loading
the viewer.
"""

from __future__ import annotations

from dataclasses import dataclass
from urllib.parse import quote

from fishswarm.protocols.hosts import url_host

WEB_PORT = 9090
"""Default port of the viewer's page."""
GRPC_PORT = 9876
"""Default port of the data stream the page reads (rerun's own default)."""


class ViewError(RuntimeError):
    """The live view cannot start (the message says why and what to do)."""


@dataclass(frozen=True)
class ViewSettings:
    """Where the view is served.

    Attributes:
        host: the name or address under which browsers reach this machine; the page tells
            the browser to stream from it (``localhost`` for a browser on this machine).
        web_port: port of the viewer's page.
        grpc_port: port of the data stream.
        open_browser: open this machine's browser on the page.
        memory_limit: how much of the run the stream keeps for pages opened late (rerun's
            size syntax); beyond, it drops the oldest.
    """

    host: str = "localhost"
    web_port: int = WEB_PORT
    grpc_port: int = GRPC_PORT
    open_browser: bool = False
    memory_limit: str = "1GiB"

    def __post_init__(self) -> None:
        for name in ("web_port", "grpc_port"):
            port = getattr(self, name)
            if not 0 < port < 65536:
                raise ValueError(f"{name} must be a port number 1–65535, got {port}")
        if self.web_port == self.grpc_port:
            raise ValueError(f"the page and the data stream need two ports, got {self.web_port}")
        url_host(self.host)  # a name browsers can reach, or an address

    @property
    def stream_url(self) -> str:
        """Where the page streams the swarm from."""
        return f"rerun+http://{url_host(self.host)}:{self.grpc_port}/proxy"

    @property
    def local_stream_url(self) -> str:
        """Where this machine sends more to the stream (a later run's recording)."""
        return f"rerun+http://127.0.0.1:{self.grpc_port}/proxy"

    @property
    def page_url(self) -> str:
        """The page to open in a browser."""
        return (
            f"http://{url_host(self.host)}:{self.web_port}/?url={quote(self.stream_url, safe='')}"
        )
