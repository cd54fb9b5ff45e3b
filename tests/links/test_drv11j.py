"""The emulated DRV-11J: frame codec (round trip, chunking, errors), the two ends, and the TCP drivers."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from manip.cougar.cli import serve_cougar
from manip.cougar.link import (
    MAX_PAYLOAD,
    Bye,
    CougarEnd,
    Drv11jError,
    Frame,
    FrameDecoder,
    Hello,
    PumaEnd,
    Role,
    Tick,
    Ticked,
    Words,
    encode_frame,
    parse_drv11j_address,
)
from manip.links.drv11j import Drv11jPort
from manip.reference_server.cougar_wrist import CougarWrist
from manip.spec.constants import CougarCommand
from tests.support.cougar_fake import FakeCougar, WristClient

words16 = st.integers(0, 0xFFFF)
frames = st.one_of(
    st.builds(Hello, st.sampled_from(Role), st.integers(0, 0xFFFF)),
    st.builds(Words, st.sampled_from(Role), st.lists(words16, max_size=40).map(tuple)),
    st.builds(Tick, st.integers(0, 0xFFFF_FFFF), st.integers(-(1 << 62), 1 << 62).map(lambda us: us / 1e6)),
    st.builds(Ticked, st.integers(0, 0xFFFF_FFFF)),
    st.builds(Bye, st.text(st.characters(min_codepoint=32, max_codepoint=126), max_size=60)),
)


@given(st.lists(frames, max_size=12), st.data())
def test_frames_round_trip_in_any_chunks(sent: list[Frame], data: st.DataObject) -> None:
    stream = b"".join(encode_frame(f) for f in sent)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=8)))
    decoder = FrameDecoder()
    got: list[Frame] = []
    for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True):
        got += decoder.feed(stream[a:b])
    assert decoder.pending == 0
    assert len(got) == len(sent)
    for g, s in zip(got, sent, strict=True):
        if isinstance(s, Tick):
            assert isinstance(g, Tick) and g.index == s.index
            assert g.time == pytest.approx(s.time, abs=1e-6)
        else:
            assert g == s


def test_a_long_word_run_is_split_over_frames() -> None:
    words = tuple(i & 0xFFFF for i in range(MAX_PAYLOAD + 10))
    got = FrameDecoder().feed(encode_frame(Words(Role.PUMA, words)))
    assert [len(f.words) for f in got if isinstance(f, Words)] == [MAX_PAYLOAD, 10]
    assert sum((f.words for f in got if isinstance(f, Words)), ()) == words


def test_the_byte_layout_is_little_endian_words() -> None:
    assert encode_frame(Hello(Role.PUMA)) == bytes([1, 0, 3, 0, 0x4A, 0x44, 1, 0, 1, 0])
    assert encode_frame(Words(Role.COUGAR, (0x1234,))) == bytes([3, 0, 1, 0, 0x34, 0x12])
    assert encode_frame(Tick(0x00010002, 1.5)) == bytes(
        [4, 0, 6, 0, 2, 0, 1, 0, 0x60, 0xE3, 0x16, 0, 0, 0, 0, 0]
    )


@pytest.mark.parametrize(
    "data",
    [
        bytes([9, 0, 0, 0]),  # unknown type
        bytes([1, 0, 3, 0, 0, 0, 1, 0, 1, 0]),  # HELLO without the magic
        bytes([4, 0, 1, 0, 0, 0]),  # TICK too short
        bytes([6, 0, 1, 0, 9, 0]),  # BYE claims 9 bytes, has none
    ],
)
def test_bad_frames_are_errors(data: bytes) -> None:
    with pytest.raises(Drv11jError):
        FrameDecoder().feed(data)


def test_the_ends_insist_on_hello_and_the_other_role() -> None:
    with pytest.raises(Drv11jError, match="HELLO"):
        PumaEnd().receive(encode_frame(Ticked(0)))
    with pytest.raises(Drv11jError, match="incompatible"):
        PumaEnd().receive(encode_frame(Hello(Role.PUMA)))
    end = CougarEnd(FakeCougar())
    end.receive(encode_frame(Hello(Role.PUMA)))
    with pytest.raises(Drv11jError, match="unexpected"):
        end.receive(encode_frame(Words(Role.COUGAR, (1,))))


def test_the_ends_carry_words_and_ticks() -> None:
    cougar = FakeCougar()
    puma, far = PumaEnd(), CougarEnd(cougar)
    assert far.receive(puma.hello()) == b""
    assert puma.receive(far.hello()) == [] and puma.peer_ready
    back = far.receive(puma.send([CougarCommand.VERS, 1]) + puma.tick(0.016))
    assert puma.receive(back) == [8, cougar.version]
    assert puma.ticks_done == 1 and far.ticks == 1
    puma.receive(far.bye("done"))
    assert puma.closed == "done"


def test_addresses() -> None:
    assert parse_drv11j_address("tcp://127.0.0.1:0") == ("127.0.0.1", 0)
    assert parse_drv11j_address("tcp://localhost") == ("localhost", 42011)
    for bad in ("udp://h:1", "tcp://:5", "tcp://h:1/x", "tcp://h:99999"):
        with pytest.raises(ValueError):
            parse_drv11j_address(bad)


# ---------------------------------------------------------------------------------- over TCP
def _run(coro: Callable[[], Awaitable[Any]]) -> Any:
    async def bounded() -> Any:
        async with asyncio.timeout(10):
            return await coro()

    return asyncio.run(bounded())


async def _answer(client: WristClient, op: str, **values: Any) -> Any:
    """Send a request; tick the session (giving the network time) until it is answered."""
    number = client.packet_no + 1
    got = client.send(op, **values)
    for _ in range(200):
        for msg in got:
            if getattr(msg, "request_number", None) == number and not hasattr(msg, "condition"):
                return msg
        await asyncio.sleep(0.004)
        got = client.tick()
    raise AssertionError(f"{op} not answered")


def test_a_puma_uses_a_cougar_over_tcp() -> None:
    async def scenario() -> None:
        cougar = FakeCougar(wall_at=-100.0)
        async with serve_cougar(cougar, "tcp://127.0.0.1:0") as server:
            port = await Drv11jPort.open(server.address)
            client = WristClient(CougarWrist(port))
            forces = await _answer(client, "read-forces")
            assert forces.values["forces"] == pytest.approx((50.0, 0, 0, 0, 0, 0))
            version = await _answer(client, "wrist-version")
            assert version.values["version"] == cougar.version
            assert port.ticks_done >= 1 and server.connections == 1
            busy = Drv11jPort(server.address)
            with pytest.raises(ConnectionError):
                for _ in range(100):
                    await asyncio.sleep(0.01)
                    if busy.error:
                        raise ConnectionError(busy.error)
            assert "busy" in (busy.error or "")
            port.close()

    _run(scenario)


def test_a_cougar_that_is_not_there_is_a_link_error() -> None:
    async def scenario() -> None:
        async with serve_cougar(FakeCougar(), "tcp://127.0.0.1:0") as server:
            address = server.address
        port = Drv11jPort(address, connect_timeout=1.0)
        client = WristClient(CougarWrist(port))
        msg = None
        for _ in range(100):
            await asyncio.sleep(0.01)
            if port.error:
                msg = await _answer(client, "read-forces")
                break
        assert msg is not None and msg.error.code == "WLK"

    _run(scenario)
