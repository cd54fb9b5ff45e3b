"""Scripted peers for the client tests: handlers of a links server
(:func:`tests.support.servers.scripted_server`) that answer a client in one fixed way, and the poses they
use."""

from __future__ import annotations

from manip.codecs.messages import encode_async
from manip.links import ChaosConnection
from manip.spec.constants import AsyncCondition, ServerOp

READY = (0.0, -90.0, 90.0, 0.0, 0.0, 0.0)
TARGET = (20.0, -70.0, 100.0, 10.0, 30.0, -15.0)


async def send_initial(conn: ChaosConnection) -> None:
    assert conn.rfc is not None
    await conn.send(conn.rfc.packet_no.to_bytes(2, "little"), ServerOp.RESPONSE)


async def reply_done(conn: ChaosConnection, number: int) -> None:
    await conn.send(number.to_bytes(2, "little"), ServerOp.RESPONSE)


async def never_answers(conn: ChaosConnection) -> None:
    await send_initial(conn)
    async for _ in conn:
        pass


async def segment_reporter(conn: ChaosConnection) -> None:
    """Answers request-notifications, then reports segments 7 and 8 completed."""
    await send_initial(conn)
    request = await conn.receive()
    await reply_done(conn, request.packet_no)
    for segment in (7, 8):
        data = encode_async(request.packet_no, AsyncCondition.SEGMENT_COMPLETED, 0, segment)
        await conn.send(data, ServerOp.ASYNCHRONOUS_RESPONSE)
    async for _ in conn:
        pass
