"""Scripted fake servers for the reference-client tests, over the in-memory transport.

:class:`FakeArm` answers every spec opcode with canned, spec-conforming data (or runs a per-opcode
script); with ``auto_reply=False`` it only sends the initial RESPONSE and leaves the peer to the test.
``tests/reference_client/test_fake_arm.py`` checks the fake itself.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Awaitable, Callable, Coroutine
from contextlib import asynccontextmanager
from typing import Any, TypeVar

from manip.arm.transform import Transform
from manip.codecs.error_string import ErrorMessage
from manip.codecs.messages import DecodedRequest, decode_request, encode_reply
from manip.reference_client import (
    ClientOptions,
    Manipulator,
    MemoryPeer,
    MemoryTransport,
    SentRequest,
    aconnect,
)
from manip.spec.constants import RequestOp, ServerOp

T = TypeVar("T")

HERE = Transform.trans(400.0, -150.0, 250.0) @ Transform.rot_z(30.0) @ Transform.rot_x(180.0)
JOINTS = (10.0, -45.0, 90.0, 0.5, -30.0, 180.0)
FORCES = (1.5, -2.0, 0.25, 10.0, -0.125, 3.0)
GAUGES = (-2048, -1, 0, 1, 100, 2047, -300, 7)
DESCRIPTION = (
    '((:brand-name . "Unimation Puma 600") (:unique-name . "Trurl") (:degrees-of-freedom . 6)'
    " (:operations 200 201 202 203 204 205 206 207 210 211 212 213 214 215 216 217 220 221)"
    " (:software-version :puma 5 :manip 14.) (:protocol-version . 1))"
)

Script = Callable[["FakeArm", SentRequest, DecodedRequest | None], Awaitable[None] | None]


def error(code: str, message: str = "", *args: int, severity: str = "E", where: str = "fake") -> ErrorMessage:
    return ErrorMessage(where, severity, code, message, tuple(args), has_nul=bool(args))


class FakeArm:
    """A fake Puma server.  ``scripts[opcode]`` overrides the canned answer for that opcode."""

    def __init__(
        self, peer: MemoryPeer, *, auto_reply: bool = True, initial_number: int | None = None
    ) -> None:
        self.peer = peer
        self.auto_reply = auto_reply
        self.initial_number = initial_number
        self.scripts: dict[int, Script] = {}
        self.decoded: list[DecodedRequest | None] = []
        self.segment = 0
        self.freed: int | None = None
        """Joint freed by the last free-joint: the next packet un-frees it (erratum free-joint-replies)."""
        self.chunk = 40
        """Text bytes per describe-self packet, so the description takes several packets."""

    async def run(self) -> None:
        await self.peer.wait_connected()
        self.peer.send_initial_response(self.initial_number)
        if not self.auto_reply:
            return
        while (sent := await self.peer.receive()) is not None:
            if self.freed is not None:  # discarded, not executed, answered with done
                self.freed = None
                self.decoded.append(None)
                self.peer.reply(sent.number)
                continue
            try:
                decoded: DecodedRequest | None = decode_request(sent.opcode, sent.data)
            except ValueError:
                decoded = None
            self.decoded.append(decoded)
            script = self.scripts.get(sent.opcode)
            if script is not None:
                result = script(self, sent, decoded)
                if result is not None:
                    await result
                continue
            self.answer(sent, decoded)

    def next_segment(self) -> int:
        self.segment = (self.segment + 1) & 0xFFFF
        return self.segment

    def answer(self, sent: SentRequest, decoded: DecodedRequest | None) -> None:
        """The canned, conforming answer."""
        n = sent.number
        if decoded is None:
            self.peer.error(
                ServerOp.NON_FATAL_ERROR, n, error("UOP", "Unknown opcode ~", sent.opcode, severity="C")
            )
            return
        op = decoded.op
        kind = op.response.form
        if kind == "done":
            if op.opcode == RequestOp.FREE_JOINT:
                joint = decoded.values["joint"]
                assert isinstance(joint, int)
                self.freed = joint
            self.peer.reply(n)
        elif kind == "segment":
            self.peer.send(ServerOp.RESPONSE, encode_reply(op.opcode, n, segment=self.next_segment()))
        elif kind == "multi":
            raw = DESCRIPTION.encode("ascii")
            self.peer.reply_multi(n, [raw[i : i + self.chunk] for i in range(0, len(raw), self.chunk)])
        else:
            self.peer.send(ServerOp.RESPONSE, encode_reply(op.opcode, n, **self.data_for(decoded)))

    def data_for(self, decoded: DecodedRequest) -> dict[str, Any]:
        match decoded.opcode:
            case RequestOp.HERE:
                return {"transform": HERE.to_floats()}
            case RequestOp.JOINT_ANGLES | RequestOp.SOLVE_FORWARDS:
                return {"joints": JOINTS}
            case RequestOp.SOLVE_BACKWARDS:
                return {"transform": HERE.to_floats()}
            case RequestOp.READ_FORCES:
                return {"forces": FORCES}
            case RequestOp.READ_RAW_GAUGES:
                return {"gauges": GAUGES}
            case RequestOp.CALIBRATE_WRIST:
                return {"offsets": GAUGES}
            case RequestOp.EXAMINE_WRIST:
                address, count = decoded.values["address"], decoded.values["count"]
                assert isinstance(address, int) and isinstance(count, int)
                return {"words": tuple((address + i) & 0xFFFF for i in range(count))}
            case RequestOp.WRIST_VERSION:
                return {"version": 0o17}
        raise AssertionError(f"no canned data for {decoded.op.name}")


@asynccontextmanager
async def session(
    fake_factory: Callable[[MemoryPeer], FakeArm] = FakeArm,
    options: ClientOptions | None = None,
    **transport_options: Any,
) -> AsyncIterator[tuple[Manipulator, FakeArm]]:
    """A connected manipulator and its fake server; both are stopped at the end."""
    transport = MemoryTransport(**transport_options)
    fake = fake_factory(transport.peer)
    task = asyncio.create_task(fake.run())
    try:
        async with aconnect(transport, options) as arm:
            yield arm, fake
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


def run(coro: Coroutine[Any, Any, T], limit: float = 5.0) -> T:
    """Run a test coroutine; a hang fails the test within ``limit`` seconds.

    Every task the test made is finished and its exception retrieved before the loop closes, so a
    failing test leaves no "exception was never retrieved" behind to be logged during a later GC.
    """

    async def guarded() -> T:
        loop = asyncio.get_running_loop()
        created: list[asyncio.Task[Any]] = []

        def factory(loop: asyncio.AbstractEventLoop, task_coro: Any, **kw: Any) -> asyncio.Task[Any]:
            task: asyncio.Task[Any] = asyncio.Task(task_coro, loop=loop, **kw)
            created.append(task)
            return task

        loop.set_task_factory(factory)
        try:
            return await asyncio.wait_for(coro, limit)
        finally:
            others = [t for t in created if t is not asyncio.current_task()]
            for task in others:
                task.cancel()
            await asyncio.gather(*others, return_exceptions=True)

    return asyncio.run(guarded())


def manual(peer: MemoryPeer) -> FakeArm:
    """A fake that sends the initial RESPONSE and leaves the rest to the test."""
    return FakeArm(peer, auto_reply=False)
