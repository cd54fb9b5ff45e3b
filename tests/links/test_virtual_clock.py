"""The virtual-clock event loop and the unix:// link that simulated runs use."""

from __future__ import annotations

import asyncio
import os
import tempfile
import time

import pytest
from hypothesis import given
from hypothesis import strategies as st

from manip.links import AddressError, open_connection, parse_address, start_server, virtual_clock
from manip.links.virtual_clock import VirtualClockLoop, is_virtual


def test_idle_time_is_skipped_and_timers_keep_their_order() -> None:
    fired: list[tuple[str, float]] = []

    async def main() -> float:
        loop = asyncio.get_running_loop()
        start = loop.time()

        async def later(name: str, delay: float) -> None:
            await asyncio.sleep(delay)
            fired.append((name, loop.time() - start))

        await asyncio.gather(later("b", 3600.0), later("a", 5.0), later("c", 7200.0))
        return loop.time() - start

    real = time.perf_counter()
    elapsed = virtual_clock.run(main(), virtual=True)
    assert time.perf_counter() - real < 2.0  # two simulated hours, not two real ones
    assert elapsed == pytest.approx(7200.0)
    assert [name for name, _ in fired] == ["a", "b", "c"]
    assert [t for _, t in fired] == pytest.approx([5.0, 3600.0, 7200.0])


@given(st.lists(st.floats(1e-12, 5.0), min_size=1, max_size=40))
def test_the_clock_lands_on_whole_nanoseconds_never_before_a_timer(delays: list[float]) -> None:
    """Every instant the clock jumps to is the float of a whole nanosecond, at or after the timer it
    jumped for: a capture's nanosecond times then name the run's instants exactly."""

    async def main() -> list[tuple[float, float]]:
        loop = asyncio.get_running_loop()
        seen = []
        for delay in delays:
            due = loop.time() + delay
            await asyncio.sleep(delay)
            seen.append((due, loop.time()))
        return seen

    for due, now in virtual_clock.run(main(), virtual=True):
        assert round(now * 1e9) / 1e9 == now
        assert now >= due - 1e-9  # a timer within the loop's 1 ns resolution is due
        assert now - due < 2e-9


def test_the_clock_stands_still_while_a_thread_works() -> None:
    async def main() -> tuple[float, bool, float]:
        loop = asyncio.get_running_loop()
        assert is_virtual(loop)
        start = loop.time()
        timer = asyncio.ensure_future(asyncio.sleep(0.01))
        await asyncio.to_thread(time.sleep, 0.05)  # real work: virtual time must not run on meanwhile
        during = loop.time() - start
        fired_early = timer.done()
        await timer
        return during, fired_early, loop.time() - start

    during, fired_early, total = virtual_clock.run(main(), virtual=True)
    assert during == 0.0
    assert not fired_early
    assert total == pytest.approx(0.01)


def test_a_deadline_expires_in_virtual_time() -> None:
    async def main() -> float:
        loop = asyncio.get_running_loop()
        start = loop.time()
        with pytest.raises(TimeoutError):
            async with asyncio.timeout(30.0):
                await asyncio.Event().wait()
        return loop.time() - start

    assert virtual_clock.run(main(), virtual=True) == pytest.approx(30.0)


def test_real_time_is_plain_asyncio() -> None:
    async def main() -> bool:
        return is_virtual()

    assert virtual_clock.run(main(), virtual=False) is False
    assert VirtualClockLoop.virtual is True


def test_unix_addresses_parse_and_print() -> None:
    addr = parse_address("unix:///tmp/x/puma.sock?me=0402")
    assert (addr.scheme, addr.path, addr.my_addr, addr.framing) == ("unix", "/tmp/x/puma.sock", 0o402, "tcp")
    assert parse_address(str(addr)) == addr
    with pytest.raises(AddressError, match="path"):
        parse_address("unix://")


@pytest.mark.parametrize("virtual", [False, True])
def test_a_chaos_connection_over_a_unix_socket(virtual: bool) -> None:
    async def main(path: str) -> tuple[bytes, float]:
        async def echo(conn):  # type: ignore[no-untyped-def]
            packet = await conn.receive()
            await conn.send(packet.data[::-1])

        server = await start_server(f"unix://{path}", "ECHO", echo)
        try:
            loop = asyncio.get_running_loop()
            start = loop.time()
            conn = await open_connection(f"unix://{path}?contact=ECHO")
            await conn.send(b"manip")
            reply = await conn.receive()
            await conn.close()
            return reply.data, loop.time() - start
        finally:
            await server.aclose()

    with tempfile.TemporaryDirectory() as directory:
        data, took = virtual_clock.run(main(os.path.join(directory, "s")), virtual=virtual)
    assert data == b"pinam"
    if virtual:
        assert took < 1.0  # nothing waited on a timer: the exchange is instant in simulated time
