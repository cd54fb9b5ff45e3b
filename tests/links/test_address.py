"""The link address syntax shared by every command and the library."""

from __future__ import annotations

import pytest

from manip.links.address import (
    DEFAULT_CHUDP_PORT,
    DEFAULT_TCP_PORT,
    AddressError,
    LinkAddress,
    parse_address,
)


def test_tcp_defaults() -> None:
    a = parse_address("tcp://127.0.0.1")
    assert a == LinkAddress("tcp", "127.0.0.1", DEFAULT_TCP_PORT)
    assert parse_address("localhost:5000").port == 5000
    assert parse_address("tcp://[::1]:7").host == "::1"


def test_chudp() -> None:
    a = parse_address("chudp://10.0.0.1:42042?addr=0440&me=0401&local=127.0.0.1:5555")
    assert (a.peer_addr, a.my_addr, a.local) == (0o440, 0o401, ("127.0.0.1", 5555))
    assert parse_address("chudp://h?addr=3040").port == DEFAULT_CHUDP_PORT
    with pytest.raises(AddressError, match="needs addr"):
        parse_address("chudp://h:1")


def test_chaosd_and_contact() -> None:
    a = parse_address("chaosd:///tmp/sock?addr=3037&contact=ROBOT")
    assert (a.path, a.peer_addr, a.contact) == ("/tmp/sock", 0o3037, "ROBOT")


@pytest.mark.parametrize(
    "url",
    [
        "tcp://h:1?me=9",  # not octal
        "tcp://h:1?addr=0400",  # host byte zero
        "udp://h:1",
        "tcp://h:1?bogus=1",
        "tcp://h:99999",
        "tcp://h:1?contact=",
    ],
)
def test_bad_addresses_say_what_is_wrong(url: str) -> None:
    with pytest.raises(AddressError):
        parse_address(url)


@pytest.mark.parametrize(
    "url",
    [
        "tcp://127.0.0.1:42085",
        "tcp://[::1]:9?contact=ARM",
        "chudp://h:1?addr=440&me=3040",
        "chaosd:///x/y?addr=3037",
    ],
)
def test_str_round_trips(url: str) -> None:
    a = parse_address(url)
    assert parse_address(str(a)) == a
