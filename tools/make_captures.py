"""Record the golden captures in captures/: small sessions with the reference server.

    python tools/make_captures.py [--out DIR] [--only NAME]

Each session runs the reference server (:func:`manip.reference_server.driver.serve`, on a free loopback
TCP port, time scale 20) and a plain client made of :func:`manip.links.open_connection` and the
message codecs, recorded on the client's side through a :class:`manip.captures.RecorderTap`.  The
client waits for every reply (and for the asynchronous notification after a move) before it sends the
next request, so the manip packets of each capture are the same on every run; only times, connection
indices, acknowledgements, checksums and idle STS/SNS traffic differ.

* ``describe-self.mcap``: the initial RESPONSE, describe-self (a multi-packet text reply), here.
* ``motion.mcap``: enable-power, request-notifications (segment completed), joint-angles,
  set-joint-angles to a nearby pose, the segment-completed asynchronous response, joint-angles, here.
* ``errors.mcap``: a move without power (error), an unknown opcode (command error), a request with
  the wrong length (command error), free-joint of joint 9 (error), then joint-angles still answers.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any, Final

from manip.captures import Recorder, RecorderTap
from manip.codecs.messages import decode_async, decode_reply, encode_request, request_op
from manip.codecs.packet import Packet
from manip.links import ChaosConnection, open_connection
from manip.reference_server.driver import serve
from manip.spec import SPEC
from manip.spec.constants import ServerOp

OUT: Final = Path(__file__).resolve().parents[1] / "captures"
TIME_SCALE: Final = 20.0
SEED: Final = 1985
REPLY_TIMEOUT: Final = 10.0


class Client:
    """Request/reply over one connection; every packet received is kept in ``received``."""

    def __init__(self, conn: ChaosConnection) -> None:
        self.conn = conn
        self.received: list[Packet] = []

    async def next(self) -> Packet:
        async with asyncio.timeout(REPLY_TIMEOUT):
            packet = await self.conn.receive()
        self.received.append(packet)
        return packet

    async def call(self, op: str, **values: Any) -> list[Packet]:
        """Send a request; return the packets that answer it, through its final reply."""
        spec_op = request_op(op)
        return await self.call_raw(
            spec_op.opcode, encode_request(op, **values), multi=spec_op.response.form == "multi"
        )

    async def call_raw(self, opcode: int, data: bytes, *, multi: bool = False) -> list[Packet]:
        number = await self.conn.send(data, opcode)
        answers: list[Packet] = []
        while True:
            packet = await self.next()
            if packet.opcode not in (ServerOp.RESPONSE, ServerOp.NON_FATAL_ERROR, ServerOp.FATAL_ERROR):
                continue
            if int.from_bytes(packet.data[:2], "little") != number:
                continue
            answers.append(packet)
            if not multi or packet.opcode != ServerOp.RESPONSE or len(packet.data) == 2:
                return answers

    async def wait_async(self, condition: int) -> Packet:
        while True:
            packet = await self.next()
            if (
                packet.opcode == ServerOp.ASYNCHRONOUS_RESPONSE
                and decode_async(packet.data).condition == condition
            ):
                return packet


async def describe_self(client: Client) -> None:
    await client.call("describe-self")
    await client.call("here")


async def motion(client: Client) -> None:
    await client.call("enable-power")
    segment_bit = SPEC.async_codes[2].notification_bit
    await client.call("request-notifications", mask=1 << segment_bit)
    (reply,) = await client.call("joint-angles")
    start = decode_reply(reply.data, "joint-angles").values["joints"]
    assert isinstance(start, tuple)
    target = tuple(float(a) + d for a, d in zip(start, (5.0, -5.0, 2.5, 0.0, 4.0, -3.0), strict=True))
    await client.call("set-joint-angles", joints=target)
    await client.wait_async(2)
    await client.call("joint-angles")
    await client.call("here")


async def errors(client: Client) -> None:
    await client.call("move", transform=(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 400.0, 100.0, 300.0))
    await client.call_raw(0o277, b"")  # not a request opcode of the spec
    await client.call_raw(request_op("here").opcode, b"\x01\x02")  # here takes no data
    await client.call("free-joint", joint=9)
    await client.call("joint-angles")


SCENARIOS: Final[dict[str, Callable[[Client], Awaitable[None]]]] = {
    "describe-self": describe_self,
    "motion": motion,
    "errors": errors,
}


async def record(name: str, path: Path) -> None:
    """Run scenario ``name`` against a fresh reference server, recording it into ``path``."""
    async with serve("tcp://127.0.0.1:0", time_scale=TIME_SCALE, seed=SEED) as server:
        with Recorder(
            path,
            how="client tap (tools/make_captures.py)",
            seed=SEED,
            command_line=["tools/make_captures.py", name],
            metadata={"scenario": name, "server": "manip reference server", "time_scale": str(TIME_SCALE)},
        ) as recorder:
            tap = RecorderTap(recorder, "client")
            conn = await open_connection(server.address, wrap_link=tap.wrap)
            client = Client(conn)
            await client.next()  # the initial RESPONSE
            await SCENARIOS[name](client)
            await conn.close()
            await server.wait_idle()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--only", choices=sorted(SCENARIOS), action="append")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    for name in args.only or SCENARIOS:
        path = args.out / f"{name}.mcap"
        asyncio.run(record(name, path))
        print(f"wrote {path} ({path.stat().st_size} bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
