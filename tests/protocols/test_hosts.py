"""Host names and addresses as certificates and the live view's links take them."""

from __future__ import annotations

import ipaddress

import pytest

from fishswarm.protocols.hosts import host_address, url_host
from fishswarm.study.view_settings import ViewSettings


def test_addresses_names_and_neither() -> None:
    assert host_address("10.0.0.2") == ipaddress.IPv4Address("10.0.0.2")
    assert host_address("::1") == ipaddress.IPv6Address("::1")
    assert host_address("base-station.local") is None
    assert host_address("*.tank.lab") is None  # a certificate's wildcard
    for bad in ("", "bad host", "a/b", "-lead.example", "x" * 64):
        with pytest.raises(ValueError, match="neither an IP address nor a host name"):
            host_address(bad)


def test_an_ipv6_address_goes_into_a_link_in_brackets() -> None:
    assert url_host("::1") == "[::1]" and url_host("fe80::2") == "[fe80::2]"
    assert url_host("127.0.0.1") == "127.0.0.1" and url_host("laptop") == "laptop"
    assert url_host("fe80::1%eth0") == "[fe80::1%25eth0]"  # a zone, escaped as URLs need
    with pytest.raises(ValueError, match="is a wildcard: give the name browsers reach"):
        url_host("*.lab")
    view = ViewSettings(host="::1", web_port=9090, grpc_port=9876)
    assert view.stream_url == "rerun+http://[::1]:9876/proxy"
    assert view.page_url.startswith("http://[::1]:9090/?url=rerun%2Bhttp%3A%2F%2F%5B%3A%3A1%5D")
    with pytest.raises(ValueError, match="host 'a b' is neither"):
        ViewSettings(host="a b")
