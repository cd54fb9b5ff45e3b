"""Fault switches of the reference client: each makes it break one rule on purpose, so that
``manip-conform client`` is shown to catch it (``tests/conformance/client/test_faults.py``).

A client runs with a :class:`ClientFaults` value (a frozen set; none by default), given in its options
(:attr:`ClientOptions.faults <manip.reference_client.options.ClientOptions.faults>`) and passed down to
the parts that misbehave; nothing reads process-wide state.  The harness's ``--fault NAME``
(``python -m manip.reference_client.harness --fault swapped-float-words``) is where a process under test
gets them, and ``manip-conform client`` passes them on in the harness command it is given;
``--list-faults`` lists them.  With none on, nothing changes.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Final

from manip.codecs.error_string import format_joint_mask
from manip.spec.faults import FaultSwitch, defect, reading
from manip.spec.model import Layout

__all__ = ["NO_FAULTS", "ClientFault", "ClientFaults"]


class ClientFault(FaultSwitch):
    """The reference client's fault switches, each declared once."""

    WRONG_REQUEST_NUMBER = defect(
        "wrong-request-number",
        "a reply is matched to the request numbered one above the number it carries",
        "client.reply-matching",
        caught_by=("client.connect.initial-response", "client.pipeline.replies-matched"),
    )
    IGNORE_ASYNC = defect(
        "ignore-async",
        "asynchronous responses (0203) are dropped",
        "client.async-routing",
        caught_by=("client.async.segment-interleaved", "client.async.guard-hits"),
    )
    ASYNC_AS_REPLY = defect(
        "async-as-reply",
        "an asynchronous response answers the oldest pending request",
        "client.async-routing",
        caught_by=("client.async.segment-interleaved", "client.async.guard-hits"),
    )
    DOLLAR_AS_NUMBER = defect(
        "dollar-as-number",
        "$ in an error message is printed as the raw number, not the joints",
        "client.error-report",
        "error-string.substitution",
        caught_by=("client.error.args-padded", "client.error.async-error-between"),
    )
    TILDE_OCTAL = defect(
        "tilde-octal",
        "~ in an error message is printed in octal",
        "client.error-report",
        "error-string.substitution",
        caught_by=("client.error.args-padded", "client.error.args-aligned"),
    )
    FATAL_AS_NON_FATAL = defect(
        "fatal-as-non-fatal",
        "a fatal error (0201) is taken as a non-fatal error of its request; the connection goes on",
        "client.fatal-ends",
        caught_by=("client.fatal.severity-f", "client.fatal.severity-bf"),
    )
    SWAPPED_FLOAT_WORDS = defect(
        "swapped-float-words",
        "the two words of each float in a reply are read in the wrong order",
        "client.reply-data",
        caught_by=("client.reply.here", "client.float.edges"),
    )
    SET_SPEED_LENGTH = defect(
        "set-speed-length",
        "set-speed carries 8 data bytes instead of one float",
        "request-data.types",
        caught_by=("client.request.set-speed",),
    )
    NEVER_ACK = defect(
        "never-ack",
        "the client's NCP acknowledges nothing (ack field 0, no STS)",
        "ncp.acknowledge",
        caught_by=("client.ncp.acknowledge",),
    )
    RESERVED_AS_ZERO = defect(
        "reserved-as-zero",
        "a reserved-operand float in a reply is read as 0.0",
        "float.reserved-operand",
        caught_by=("client.float.reserved-operand",),
    )
    NO_INITIAL_WAIT = defect(
        "no-initial-wait",
        "requests go out without waiting for the initial RESPONSE",
        "client.initial-response",
        caught_by=("client.connect.initial-response",),
    )
    IGNORE_PAD = defect(
        "ignore-pad",
        "the numbers of an error string are read right after the NUL, a pad byte included",
        "client.error-report",
        "client.error-args-layout",
        "error-string.substitution",
        caught_by=("client.error.args-padded",),
    )
    MULTI_FIRST_PACKET = defect(
        "multi-first-packet",
        "a multi-packet reply ends at its first packet",
        "client.multi-packet",
        caught_by=("client.describe.split-mid-token", "client.describe.many-packets"),
    )
    EARLY_TIMEOUT = defect(
        "early-timeout",
        "a request times out at half its timeout",
        "client.reply-wait",
        caught_by=("client.timing.reply-near-timeout", "client.timing.no-reply"),
    )
    SILENT_CLOSE = defect(
        "silent-close",
        "the end of the connection is not reported; requests in flight wait for their timeout",
        "client.connection-lost",
        caught_by=("client.conn.cls-mid-request",),
    )
    IGNORE_WINDOW = defect(
        "ignore-window",
        "the client's NCP ignores the window the server offers (OPN and STS read as the largest window)",
        "ncp.window",
        caught_by=("client.ncp.window", "client.ncp.window-opens-late", "client.ncp.window-shrinks"),
    )
    ARRIVAL_ORDER = defect(
        "arrival-order",
        "a reply is matched to the oldest request waiting, whatever number it carries (by arrival order)",
        "client.reply-matching",
        caught_by=("client.pipeline.interleaved",),
    )
    GUARD_ZERO = defect(
        "guard-zero",
        "a new guard always gets number 0, armed or not",
        "client.guard-numbers",
        caught_by=("client.choice.guard-numbers",),
    )
    NO_NEWWC = defect(
        "no-newwc",
        "a change of load sends set frame vector but never set weight (NEWWC)",
        "client.newwc-on-load",
        caught_by=("client.choice.newwc-on-load",),
    )
    NEWWC_UNDER_GUARD = defect(
        "newwc-under-guard",
        "a change of load sends set weight while guards are armed",
        "client.no-newwc-with-guard",
        caught_by=("client.choice.no-newwc-with-guard",),
    )
    IGNORE_WINDOW_SHRINK = defect(
        "ignore-window-shrink",
        "the client's NCP keeps the widest window the server offered: a window shrunk by an STS is ignored",
        "ncp.window",
        caught_by=("client.ncp.window-shrinks",),
    )
    WINDOW_ON_NEW_ACK_ONLY = defect(
        "window-on-new-ack-only",
        "the client's NCP reads an STS's window only when the STS acknowledges something new",
        "ncp.window",
        caught_by=("client.ncp.window-shrinks", "client.ncp.window-opens-by-status"),
    )
    GUARD_ALWAYS_CONTINUE = defect(
        "guard-always-continue",
        "arm-guard arms every guard as one that lets the move continue (bit 15 of set guard's first word "
        "clear even when the guard should stop the move)",
        "client.guard-word",
        caught_by=("client.choice.guard-numbers",),
    )
    NO_NEWWC_WITHOUT_OFFSET = defect(
        "no-newwc-without-offset",
        "a change of load without a new frame vector sends nothing (no set weight, NEWWC)",
        "client.newwc-on-load",
        caught_by=("client.choice.newwc-without-offset", "client.choice.plain-guards"),
    )
    PLAIN_GUARDS_UNTRACKED = defect(
        "plain-guards-untracked",
        "guards armed and cleared by plain set guard and clear guard requests are not tracked: arm-guard "
        "may reuse their numbers, and a change of load ignores them",
        "client.guard-numbers",
        "client.no-newwc-with-guard",
        "client.newwc-on-load",
        caught_by=("client.choice.plain-guards",),
    )
    ASYNC_TO_WAITING = defect(
        "async-to-waiting-request",
        "an asynchronous response (0203) arriving while a request waits is handed to that request's "
        "handler: reported with that request's op and request number",
        "client.async-routing",
        caught_by=(
            "client.async.segment-interleaved",
            "client.async.guard-hits",
            "client.pipeline.interleaved",
        ),
    )
    CHOICE_ERROR_UNNUMBERED = defect(
        "choice-error-unnumbered",
        "a choice operation's server error is reported with request_number null, as its reply is, not the "
        "number the error carries",
        "client.error-report",
        caught_by=("client.choice.errors",),
    )
    ASYNC_ERROR_TO_WAITING = defect(
        "async-error-to-waiting-request",
        "an asynchronous error or warning (0204, 0205) arriving while a request waits is reported with that "
        "request's op and request number",
        "client.async-routing",
        "client.error-report",
        caught_by=(
            "client.error.async-error-between",
            "client.error.warning-between",
            "client.pipeline.interleaved",
        ),
    )
    STRAY_UNSIGNALLED = defect(
        "stray-unsignalled",
        "a RESPONSE whose request number matches no request is dropped without a word: no out-of-sequence "
        "signal to the user",
        "client.out-of-sequence",
        caught_by=("client.reply.out-of-sequence",),
    )
    MOVE_ROW_MAJOR = defect(
        "move-row-major",
        "move and straight-line move send their transform row after row (nx ox ax px, ny ...) instead of "
        "column after column as Here lays it out (N O A P)",
        "move.transform-data",
        caught_by=("client.request.move", "client.request.straight-move"),
    )
    SOLVE_OPCODES_SWAPPED = defect(
        "solve-opcodes-swapped",
        "solve forwards goes out under solve backwards' opcode and solve backwards under solve forwards' "
        "(two lines of the opcode table swapped), each with its own data",
        "request.opcode-range",
        "request-data.types",
        caught_by=("client.request.solve-forwards", "client.request.solve-backwards"),
    )
    ALWAYS_PAD = defect(
        "always-pad",
        "the numbers of an error string are always read after a pad byte, as if the server had aligned "
        "them to a word, even when the bytes after the NUL are even (none)",
        "client.error-args-layout",
        caught_by=("client.error.args-unpadded",),
    )
    NO_CLS = defect(
        "no-cls",
        "the client's NCP ends a connection by dropping its link: the CLS of the close never goes out",
        "client.close",
        caught_by=("client.close.sequence",),
    )
    CLEAR_GUARDS_FIRST = reading(
        "clear-guards-first",
        "no fault: a change of load with guards armed clears them first (a clear guard each), then sends "
        "the load's requests, instead of refusing; docs/client-harness.md allows both, so the suite must "
        "pass it",
    )
    LITERAL_EXAMPLES = reading(
        "literal-examples",
        "no fault: the harness takes every example of docs/client-harness.md literally where the contract "
        "allows two readings (a one-element raw as a bare string, as the segment example; state lost after "
        "the not-connected errors of the requests in flight); the suite must pass it",
    )


class ClientFaults(frozenset[ClientFault]):
    """The faults a reference client runs with: a frozen set of :class:`ClientFault`."""

    @classmethod
    def parse(cls, names: Iterable[str]) -> ClientFaults:
        """Faults by name (blank names skipped); ValueError naming the known ones for a name that is not."""
        return cls(ClientFault.parse(names, "client fault"))

    def render_message(self, message: str, args: tuple[int, ...], has_nul: bool) -> str | None:
        """The message as a faulty client renders it, or None when no rendering fault is on."""
        dollar, tilde = ClientFault.DOLLAR_AS_NUMBER in self, ClientFault.TILDE_OCTAL in self
        if not (dollar or tilde) or not has_nul:
            return None
        it = iter(args)
        out: list[str] = []
        for ch in message:
            arg = next(it, None) if ch in "~$" else None
            if arg is None:
                out.append(ch)
            elif ch == "~":
                out.append(f"{arg:o}" if tilde else str(arg))
            else:
                out.append(str(arg) if dollar else format_joint_mask(arg))
        return "".join(out)

    def read_floats(self, layout: Layout, data: bytes) -> bytes:
        """Reply data (after the request number) as a client with the float faults on reads them."""
        reserved_as_zero, swapped = (
            ClientFault.RESERVED_AS_ZERO in self,
            ClientFault.SWAPPED_FLOAT_WORDS in self,
        )
        if not (reserved_as_zero or swapped):
            return data
        out = bytearray(data)
        pos = 0
        for f in layout.fields:
            size = 4 if f.type.element == "float" else 2
            count = f.type.count
            if count is None:  # variable-length fields come last and hold no floats
                break
            for _ in range(count):
                if size == 4 and pos + 4 <= len(out):
                    high, low = out[pos + 1], out[pos]  # the sign/exponent word, low byte first
                    reserved = high & 0x80 and not high & 0x7F and not low & 0x80
                    if reserved_as_zero and reserved:
                        out[pos : pos + 4] = bytes(4)
                    if swapped:
                        out[pos : pos + 4] = out[pos + 2 : pos + 4] + out[pos : pos + 2]
                pos += size
        return bytes(out)


NO_FAULTS: Final = ClientFaults()
"""A conforming client."""
