"""Host names and IP addresses as a swarm's certificates and its live view's links take
them: checked once, where a user gives one, and written into a URL as it must be."""

from __future__ import annotations

import ipaddress
import re

HOST_NAME = re.compile(r"(\*\.)?(?!-)[A-Za-z0-9-]{1,63}(?<!-)(\.(?!-)[A-Za-z0-9-]{1,63}(?<!-))*\.?")
"""A DNS name: labels of letters, digits and '-' joined by dots, a leading ``*.`` for a
wildcard (as a certificate may hold it), a trailing dot for a fully qualified name."""


def host_address(host: str) -> ipaddress.IPv4Address | ipaddress.IPv6Address | None:
    """The IP address ``host`` is; None for a host name.

    Raises:
        ValueError: ``host`` is neither (the message says what a host may be).
    """
    try:
        return ipaddress.ip_address(host)
    except ValueError:
        if not HOST_NAME.fullmatch(host):
            raise ValueError(
                f"host {host!r} is neither an IP address nor a host name (letters, digits "
                "and '-', parts joined by '.')"
            ) from None
    return None


def url_host(host: str) -> str:
    """``host`` as the host part of a URL: an IPv6 address in brackets (``[::1]``, a zone
    written ``%25``, as URLs escape ``%``).

    Raises:
        ValueError: ``host`` is neither an IP address nor a host name (a wildcard, which a
            certificate may hold, is no address a browser can reach).
    """
    if host.startswith("*"):
        raise ValueError(f"host {host!r} is a wildcard: give the name browsers reach")
    address = host_address(host)
    if isinstance(address, ipaddress.IPv6Address):
        return f"[{host.replace('%', '%25')}]"
    return host
