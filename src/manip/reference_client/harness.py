"""The reference client's harness for ``manip-conform client`` (``docs/client-harness.md``, contract 1).

``python -m manip.reference_client.harness [--fault NAME]...`` (also ``manip-client harness``) reads
case instructions on stdin and performs them with the reference client's public API, writing what the
client saw as JSON result lines on stdout; logs go to stderr.  ``--fault NAME`` switches on a fault of
the client (:mod:`.faults`) so the suite is shown to catch it; ``--list-faults`` lists them.  The faults
are read here, at the entry point, into one :class:`~manip.reference_client.faults.ClientFaults` value
that every case's client gets in its options (``manip-conform client -- python -m
manip.reference_client.harness --fault NAME`` passes them through).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import sys
from collections.abc import Callable, Mapping, Sequence
from importlib.metadata import PackageNotFoundError, version
from typing import Any, Final

from manip.codecs.messages import response_layout
from manip.commandline import configure_logging
from manip.reference_client.connect import open_manipulator
from manip.reference_client.errors import (
    AsynchronousError,
    AsynchronousWarning,
    ConnectionLostError,
    FatalError,
    JointFreedError,
    ManipError,
    NonFatalError,
    OutOfSequenceResponse,
    RequestTimeout,
    ResponseDataError,
    ServerError,
)
from manip.reference_client.extractors import extract_done, extract_segment, extract_text, extract_values
from manip.reference_client.faults import NO_FAULTS, ClientFault, ClientFaults
from manip.reference_client.guards import WristBook
from manip.reference_client.manipulator import Manipulator
from manip.reference_client.options import ClientOptions
from manip.reference_client.request import Request
from manip.spec import SPEC
from manip.spec.model import Layout

__all__ = ["CONTRACT", "main", "run_harness"]

CONTRACT: Final = 1
NAME: Final = "manip-reference-client"
CONTROL: Final = ("connect", "close", "wait", "await-replies")
CHOICES: Final = ("arm-guard", "change-load")
"""The operations that leave a choice to the client (contract revision 2), done with :class:`WristBook`."""
ASYNC_HANDLERS: Final = {1: "guard-hit", 2: "segment-completed"}
ERROR_ORIGINS: Final[tuple[tuple[type[ServerError], str], ...]] = (
    (FatalError, "fatal-error"),
    (NonFatalError, "non-fatal-error"),
    (AsynchronousError, "asynchronous-error"),
    (AsynchronousWarning, "asynchronous-warning"),
)

Emit = Callable[[dict[str, Any]], None]
log = logging.getLogger("manip.harness")


def _version() -> str:
    try:
        return version("manip")
    except PackageNotFoundError:
        return "0"


def hello(operations: Sequence[str] | None = None) -> dict[str, Any]:
    """The hello line; ``operations`` limits what it declares (to see the suite report the rest
    unsupported)."""
    declared = [*CONTROL, *CHOICES, *(op.name for op in SPEC.requests.values())]
    if operations is not None:
        declared = [op for op in declared if op in operations]
    return {
        "type": "hello",
        "contract": CONTRACT,
        "name": NAME,
        "version": _version(),
        "links": ["tcp", "chudp", "chaosd"],
        "operations": declared,
        "features": ["pipeline"],
    }


def _json_value(value: Any) -> Any:
    if isinstance(value, tuple | list):
        return [_json_value(v) for v in value]
    if isinstance(value, float):
        return value
    if isinstance(value, int):
        return value
    return str(value)


def raw_fields(layout: Layout, data: bytes) -> dict[str, list[str]]:
    """The reply's fields as received, in hex: a float as its two words, sign/exponent word first."""
    out: dict[str, list[str]] = {}
    pos = 0
    for f in layout.fields:
        element, count = f.type.element, f.type.count
        if element == "counted":
            n = int.from_bytes(data[pos : pos + 2], "little")
            pos += 2
            count, element = n, "word"
        if count is None:
            break
        items: list[str] = []
        for _ in range(count):
            if element == "float":
                w0 = int.from_bytes(data[pos : pos + 2], "little")
                w1 = int.from_bytes(data[pos + 2 : pos + 4], "little")
                items.append(f"{w0:04X}{w1:04X}")
                pos += 4
            else:
                items.append(f"{int.from_bytes(data[pos : pos + 2], 'little'):04X}")
                pos += 2
        out[f.name] = items
    return out


class CaseRun:
    """One case: its operations performed in order with the reference client."""

    def __init__(self, instruction: Mapping[str, Any], emit: Emit, faults: ClientFaults = NO_FAULTS) -> None:
        self.faults = faults
        self.case = str(instruction.get("case"))
        self.address = str(instruction.get("target"))
        self.contact = str(instruction.get("contact") or "PUMA")
        self.timeout = float(instruction.get("timeout") or 5.0)
        self.operations: list[Mapping[str, Any]] = list(instruction.get("operations") or [])
        self._emit = emit
        self.arm: Manipulator | None = None
        self.wrist: WristBook | None = None
        self.ended = False
        self.closing = False
        self.pending: list[asyncio.Task[None]] = []
        self.in_flight: set[asyncio.Task[None]] = set()
        self._late: list[asyncio.Task[None]] = []
        self._fatal_reported: set[int] = set()
        self.waiting: list[tuple[int | None, Request[Any]]] = []
        """(op id, request) of each request op waiting for its answer, oldest first."""

    def emit(self, result_type: str, op: int | None, /, **fields: Any) -> None:
        self._emit({"type": result_type, "case": self.case, "op": op, **fields})

    async def run(self) -> None:
        for op in self.operations:
            await self.perform(op)
        await self.await_replies()
        if self.arm is not None and not self.ended:
            self.closing = True
            await self.arm.aclose()
        await asyncio.gather(*self._late, return_exceptions=True)
        self.emit("done", None)

    async def perform(self, op: Mapping[str, Any]) -> None:
        name = str(op.get("op"))
        ident = op.get("id")
        ident = ident if isinstance(ident, int) else None
        if name == "connect":
            await self.connect(ident)
        elif name == "close":
            await self.close(ident)
        elif name == "wait":
            await asyncio.sleep(float(op.get("seconds") or 0.0))
        elif name == "await-replies":
            await self.await_replies()
        elif name in SPEC.requests_by_name or name in CHOICES:
            perform = self.request if name in SPEC.requests_by_name else self.choose
            task = asyncio.get_running_loop().create_task(perform(ident, name, op))
            self.in_flight.add(task)
            task.add_done_callback(self.in_flight.discard)
            if op.get("pipeline"):
                self.pending.append(task)
                await asyncio.sleep(0)  # let it be queued before the next op
            else:
                await task
        else:
            self.emit("unsupported", ident, operation=name)

    async def connect(self, ident: int | None) -> None:
        options = ClientOptions(
            timeout=self.timeout,
            connect_timeout=self.timeout,
            contact=self.contact,
            close_timeout=1.0,
            faults=self.faults,
        )
        try:
            arm = await open_manipulator(self.address, options)
        except ServerError as exc:
            self.report_error(ident, exc)
            self.emit("state", ident, state="refused", reason=str(exc))
            self.ended = True
            return
        except (ManipError, OSError, ValueError) as exc:
            reason = exc.reason if isinstance(exc, ConnectionLostError) else str(exc)
            self.emit("state", ident, state="refused", reason=reason)
            self.ended = True
            return
        self.arm = arm
        self.wrist = WristBook(arm, faults=self.faults)
        arm.add_async_listener(self.on_async)
        arm.add_error_listener(self.on_error)
        arm.add_close_listener(self.on_close)
        self.emit("state", ident, state="connected")

    async def close(self, ident: int | None) -> None:
        await self.await_replies()
        if self.arm is None or self.ended:
            return
        self.closing = True
        await self.arm.aclose()
        self.ended = True
        self.emit("state", ident, state="closed")

    async def await_replies(self) -> None:
        pending, self.pending = self.pending, []
        if pending:
            await asyncio.gather(*pending, return_exceptions=True)

    # ------------------------------------------------------------------ requests

    async def request(self, ident: int | None, name: str, op: Mapping[str, Any]) -> None:
        arm = self.arm
        if arm is None or self.ended or arm.closed:
            self.emit(
                "error",
                ident,
                origin="client",
                kind="not-connected",
                request_number=None,
                detail="the connection is not open",
            )
            return
        spec = SPEC.requests_by_name[name]
        timeout = op.get("timeout")
        kind = spec.response.form
        extractor: Any = {"done": extract_done, "segment": extract_segment, "multi": extract_text}.get(
            kind, extract_values
        )
        try:
            request: Request[Any] = arm.make_request(
                name,
                fields=dict(op.get("args") or {}),
                extractor=extractor,
                timeout=float(timeout) if timeout is not None else self.timeout,
            )
            future = arm.send_request(request)
        except (ValueError, TypeError, JointFreedError) as exc:
            self.emit(
                "error", ident, origin="client", kind="refused-locally", request_number=None, detail=str(exc)
            )
            return
        self.note_guard(name, op.get("args"), armed=True)
        waiting = (ident, request)
        self.waiting.append(waiting)
        try:
            value = await future
        except ServerError as exc:
            self.note_guard(name, op.get("args"), armed=False)  # a set guard refused arms nothing
            self.report_error(ident, exc)
            return
        except ManipError as exc:
            self.report_client_error(ident, request, exc)
            return
        finally:
            self.waiting.remove(waiting)
        self.report_reply(ident, name, request, value)

    def note_guard(self, name: str, args: Any, *, armed: bool) -> None:
        """Tell the wrist book of a guard armed or cleared by a plain set guard or clear guard request
        (armed from the moment it is sent; a set guard answered by an error arms nothing)."""
        if self.wrist is None or not isinstance(args, dict):
            return
        if name == "set-guard" and isinstance(args.get("type_index"), int):
            if armed:
                self.wrist.note_set_guard(args["type_index"])
            else:
                self.wrist.note_clear_guard(args["type_index"])
        elif name == "clear-guard" and armed and isinstance(args.get("index"), int):
            self.wrist.note_clear_guard(args["index"])

    async def choose(self, ident: int | None, name: str, op: Mapping[str, Any]) -> None:
        """A choice operation: arm-guard (the client picks the number) or change-load."""
        if self.wrist is None or self.ended or self.arm is None or self.arm.closed:
            self.emit("error", ident, origin="client", kind="not-connected", request_number=None, detail="")
            return
        args = dict(op.get("args") or {})
        timeout = float(op.get("timeout") or self.timeout)
        values: dict[str, Any] = {}
        try:
            if name == "arm-guard":
                values["guard"] = await self.wrist.arm_guard(
                    args["dvec"], args["tol"], stop=bool(args.get("stop", True)), timeout=timeout
                )
            else:
                await self.wrist.change_load(args["weight"], args["cg"], args.get("offset"), timeout=timeout)
        except (ValueError, TypeError, KeyError) as exc:
            self.emit(
                "error", ident, origin="client", kind="refused-locally", request_number=None, detail=str(exc)
            )
            return
        except ServerError as exc:
            unnumbered = ClientFault.CHOICE_ERROR_UNNUMBERED in self.faults
            self.report_error(ident, exc, unnumbered=unnumbered)
            return
        except ManipError as exc:
            kind = (
                "timeout"
                if isinstance(exc, RequestTimeout)
                else "not-connected"
                if isinstance(exc, ConnectionLostError)
                else "other"
            )
            self.emit("error", ident, origin="client", kind=kind, request_number=None, detail=str(exc))
            return
        self.emit("reply", ident, request=name, request_number=None, values=values, raw={})

    def report_reply(self, ident: int | None, name: str, request: Request[Any], value: Any) -> None:
        spec = SPEC.requests_by_name[name]
        data = b"".join(request.responses)
        kind = spec.response.form
        values: dict[str, Any]
        raw: dict[str, Any]
        if kind == "done":
            values, raw = {}, {}
        elif kind == "segment":
            values, raw = {"segment": value}, {"segment": f"{int(value):04X}"}
        elif kind == "multi":
            values, raw = {"text": value}, {"text": data.hex().upper()}
        else:
            values = {k: _json_value(v) for k, v in dict(value).items()}
            raw = raw_fields(response_layout(spec), data)
            if ClientFault.LITERAL_EXAMPLES in self.faults:  # one element as a bare string
                counted = {f.name for f in response_layout(spec).fields if f.type.element == "counted"}
                raw = {k: v[0] if len(v) == 1 and k not in counted else v for k, v in raw.items()}
        self.emit("reply", ident, request=name, request_number=request.packet_number, values=values, raw=raw)

    def report_client_error(self, ident: int | None, request: Request[Any], exc: ManipError) -> None:
        if isinstance(exc, RequestTimeout):
            kind = "timeout"
        elif isinstance(exc, ResponseDataError):
            kind = "bad-data"
        elif isinstance(exc, ConnectionLostError):
            kind = "not-connected"
        else:
            kind = "other"
        self.emit(
            "error", ident, origin="client", kind=kind, request_number=request.packet_number, detail=str(exc)
        )

    def report_error(
        self, ident: int | None, exc: ServerError, *, unnumbered: bool = False, number: int | None = None
    ) -> None:
        """A server's error; ``unnumbered`` (fault choice-error-unnumbered) leaves its number out,
        ``number`` (fault async-error-to-waiting-request) puts another in its place."""
        origin = next((o for cls, o in ERROR_ORIGINS if isinstance(exc, cls)), "non-fatal-error")
        if isinstance(exc, FatalError):
            self._fatal_reported.add(id(exc.error))
        self.emit(
            "error",
            ident,
            origin=origin,
            request_number=None if unnumbered else exc.request_number if number is None else number,
            where=exc.where,
            severity=exc.severity,
            code=exc.code,
            template=exc.template,
            arguments=list(exc.arguments),
            message=exc.message,
            rendered=exc.rendered,
        )
        if isinstance(exc, FatalError):
            self.lost(f"fatal error: {exc.rendered}")

    def lost(self, reason: str) -> None:
        if not self.ended and not self.closing:
            self.ended = True
            if ClientFault.LITERAL_EXAMPLES in self.faults:  # after the in-flight requests' errors
                self._late.append(asyncio.get_running_loop().create_task(self._lost_after(reason)))
                return
            self.emit("state", None, state="lost", reason=reason)

    async def _lost_after(self, reason: str) -> None:
        flying = [t for t in self.in_flight if t is not asyncio.current_task()]
        await asyncio.gather(*flying, return_exceptions=True)
        self.emit("state", None, state="lost", reason=reason)

    # ------------------------------------------------------------------ listeners

    def on_async(self, response: Any) -> None:
        op, number = None, response.request_number
        if ClientFault.ASYNC_TO_WAITING in self.faults and self.waiting:
            op, request = self.waiting[0]  # handed to the waiting request's handler
            number = request.packet_number
        self.emit(
            "async",
            op,
            request_number=number,
            code=response.condition,
            word2=response.word2,
            word3=response.word3,
            handler=ASYNC_HANDLERS.get(response.condition, "unknown"),
        )

    def on_error(self, error: ManipError) -> None:
        if isinstance(error, FatalError):
            if id(error.error) not in self._fatal_reported and error.request is None:
                self.report_error(None, error)
            return
        if isinstance(error, AsynchronousError | AsynchronousWarning):
            if ClientFault.ASYNC_ERROR_TO_WAITING in self.faults and self.waiting:
                op, request = self.waiting[0]  # taken for the waiting request's
                self.report_error(op, error, number=request.packet_number)
                return
            self.report_error(None, error)
        elif isinstance(error, OutOfSequenceResponse):
            self.emit(
                "error",
                None,
                origin="client",
                kind="out-of-sequence",
                request_number=error.request_number,
                detail=str(error),
            )
        else:
            log.info("%s: %s", self.case, error)

    def on_close(self, error: ManipError) -> None:
        if isinstance(error, FatalError):
            self.lost(f"fatal error: {error.rendered}")
        else:
            self.lost(error.reason if isinstance(error, ConnectionLostError) else str(error))


def _writer(stream: Any) -> Emit:
    def emit(obj: dict[str, Any]) -> None:
        stream.write(json.dumps(obj) + "\n")
        stream.flush()

    return emit


async def run_harness(
    lines: Callable[[], Any],
    emit: Emit,
    operations: Sequence[str] | None = None,
    faults: ClientFaults = NO_FAULTS,
) -> None:
    """Say hello, then run each case read from ``lines()`` (an awaitable of one line, "" at the end)
    with a client that has ``faults``."""
    emit(hello(operations))
    while True:
        line = await lines()
        if not line:
            return
        line = line.strip()
        if not line:
            continue
        try:
            instruction = json.loads(line)
        except json.JSONDecodeError as exc:
            log.error("not JSON: %s", exc)
            continue
        if not isinstance(instruction, dict) or instruction.get("type") != "case":
            log.error("not a case instruction: %.200s", line)
            continue
        await CaseRun(instruction, emit, faults).run()


def main(argv: Sequence[str] | None = None, *, prog: str = "python -m manip.reference_client.harness") -> int:
    parser = argparse.ArgumentParser(
        prog=prog,
        description="The reference client's harness for manip-conform client (docs/client-harness.md).",
    )
    parser.add_argument(
        "--fault",
        action="append",
        default=[],
        metavar="NAME",
        help="switch on a fault of the client (see --list-faults)",
    )
    parser.add_argument("--list-faults", action="store_true", help="list the client's fault switches")
    parser.add_argument(
        "--operations",
        metavar="OP,OP",
        default=None,
        help="declare only these operations in the hello (the suite reports the others' cases unsupported)",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log to stderr")
    args = parser.parse_args(argv)
    if args.list_faults:
        for fault in ClientFault:
            print(f"{fault.value:24} {fault.breaks} [{', '.join(fault.clauses)}]")
        return 0
    try:
        faults = ClientFaults.parse(args.fault)
    except ValueError as exc:
        parser.error(str(exc))
    configure_logging(logging.INFO if args.verbose else logging.ERROR)

    async def read() -> str:
        return await asyncio.to_thread(sys.stdin.readline)

    operations = None if args.operations is None else [o.strip() for o in args.operations.split(",")]
    asyncio.run(run_harness(read, _writer(sys.stdout), operations, faults))
    return 0


if __name__ == "__main__":
    sys.exit(main())
