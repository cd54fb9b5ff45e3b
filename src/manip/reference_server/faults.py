"""Fault switches of the reference server: conditions and defects injected on purpose.

A conformance suite is only as good as the defects it catches.  Each switch here makes the reference
server either meet a condition of the arm's world (``environment`` faults: the panic button, an obstacle,
a calibration failure; the server stays conformant and the suite can check how it reports them) or break
exactly one rule of the protocol (``protocol`` faults).  Running the suite against the server with each
protocol fault on, one at a time, shows whether some case catches it (mutation testing of the suite).

:data:`FAULTS` describes every switch: its name, one line saying what changes, the clause ids involved
(for a protocol fault the clauses it violates, for an environment fault the clauses whose behaviour it
triggers) and, when it takes one, what its argument means.  :class:`FaultSet` is the set a server runs
with; :meth:`FaultSet.parse` reads the ``NAME`` / ``NAME=ARG`` form a command line gives.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Final, Literal

from manip.arm.sim import Obstacle, Sluggish
from manip.spec import SPEC

__all__ = ["FAULTS", "RETIRED", "WRIST_SIDE", "Fault", "FaultInfo", "FaultSet"]


class Fault(enum.StrEnum):
    """Names of the fault switches."""

    # environment
    PANIC_BUTTON = "panic-button"
    OBSTACLE = "obstacle"
    CALIBRATE_NZI = "calibrate-nzi"
    SLUGGISH_JOINT = "sluggish-joint"
    WRIST_SILENT = "wrist-silent"
    # protocol defects
    WRONG_REQUEST_NUMBER = "wrong-request-number"
    ECHO_ACK_NUMBER = "echo-ack-number"
    NO_INITIAL_RESPONSE = "no-initial-response"
    INITIAL_RESPONSE_NUMBER = "initial-response-wrong-number"
    NO_DESCRIBE_TERMINATOR = "no-describe-terminator"
    DESCRIBE_TERMINATOR_OVERTAKEN = "describe-terminator-overtaken"
    MULTI_WRONG_NUMBER = "multi-wrong-number"
    NO_PROTOCOL_VERSION = "no-protocol-version"
    SWAPPED_FLOAT_WORDS = "swapped-float-words"
    WRONG_SEVERITY = "wrong-severity"
    ERROR_WITHOUT_COLON = "error-without-colon"
    ERROR_PAD_MISPLACED = "error-pad-misplaced"
    UOP_OPCODE_SWAPPED = "uop-opcode-byte-swapped"
    BDL_COUNTS_SWAPPED = "bdl-counts-byte-swapped"
    JOINT_MASK_SWAPPED = "joint-mask-byte-swapped"
    UNKNOWN_OPCODE_ANSWERED = "unknown-opcode-answered"
    LENGTH_UNCHECKED = "length-unchecked"
    EXTRA_REPLY_AFTER_ERROR = "extra-reply-after-error"
    FATAL_WITHOUT_CLOSE = "fatal-without-close"
    NO_JOR = "no-jor"
    SWAP_TOR_JOR = "swap-tor-jor"
    NO_NAP = "no-nap"
    AWA_IGNORED = "awa-ignored"
    AWA_REFUSES_ALL = "awa-refuses-all"
    SPEED_UNCHECKED = "speed-unchecked"
    SEGMENT_NUMBER_STUCK = "segment-number-stuck"
    UNREQUESTED_ASYNC = "unrequested-async"
    ASYNC_STRAY_BYTE = "async-stray-byte"
    FREE_JOINT_EXECUTES = "free-joint-executes"
    DESCRIBE_EXTRA_OPERATION = "describe-extra-operation"
    DESCRIBE_MISSING_OPERATION = "describe-missing-operation"
    DESCRIBE_WRONG_DOF = "describe-wrong-dof"
    DESCRIBE_NARROW_LIMITS = "describe-narrow-limits"
    DESCRIBE_LIMITS_SHORT = "describe-limits-short"
    DESCRIBE_READY_OFF = "describe-ready-off"
    WARNING_INTERRUPTS = "warning-interrupts"
    GUARD_HIT_WORD_SWAPPED = "guard-hit-word-swapped"
    STRAIGHT_AS_JOINT = "straight-as-joint"
    INCREMENT_FROM_ACTUAL = "increment-from-actual"
    INCREMENT_O_T_SWAPPED = "increment-o-t-swapped"
    CONFIGURATION_IGNORED = "configuration-ignored"
    KEEPS_SPEED = "connection-keeps-speed"
    KEEPS_CONFIGURATION = "connection-keeps-configuration"
    KEEPS_NOTIFICATIONS = "connection-keeps-notifications"
    READY_LEAVES_WRIST = "ready-leaves-wrist"
    SEGMENT_REPORT_PREVIOUS = "segment-report-previous"
    COLLISION_UNCHECKED = "collision-unchecked"
    CLOSE_KEEPS_MOVING = "close-keeps-moving"
    SEGMENTS_STOP = "segments-stop"
    SERVO_DOUBLE_RATE = "servo-double-rate"
    WRIST_TIMEOUT_SILENT = "wrist-timeout-silent"
    UNDERFLOW_DIRTY_ZERO = "underflow-dirty-zero"
    NOT_FINITE_RESERVED = "not-finite-reserved"
    FATAL_NUMBER_PREVIOUS = "fatal-number-previous"
    FATAL_SEVERITY_E = "fatal-severity-e"
    FATAL_DROPS_LINK = "fatal-drops-link"
    ASYNC_NUMBER_PREVIOUS = "async-number-previous"
    WRIST_ERROR_FATAL = "wrist-error-fatal"
    ABORT_KEEPS_QUEUE = "abort-keeps-queue"
    SPEED_IGNORED = "speed-ignored"
    QUEUE_REVERSED = "queue-reversed"
    # protocol defects of the Puma's side of the wrist link (judged by manip-conform run --puma)
    WRIST_FLOAT_WORDS_SWAPPED = "wrist-float-words-swapped"
    WRIST_USER_FIRST = "wrist-user-first"
    WRIST_NO_WAIT = "wrist-no-wait"
    READ_FORCES_NO_ANGLES = "read-forces-no-angles"
    NPR_SKIPPED = "npr-skipped"
    COMPLIANT_COLLISION_TEST = "compliant-collision-test"
    COMPLIANT_SNAP_BACK = "compliant-snap-back"
    GUARD_IGNORED = "guard-ignored"
    GUARD_UNREPORTED = "guard-unreported"
    CALIBRATE_ONE_POSE = "calibrate-one-pose"
    # protocol defects found from outside (issue 32)
    FATAL_EOF_WITHOUT_CLS = "fatal-eof-without-cls"
    KEEPS_ABORT = "connection-keeps-abort"
    NZI_MASK_SHIFTED = "nzi-mask-shifted"
    CONFIGURATION_SWAPPED = "configuration-swapped"
    JOINTS_REVERSED = "joints-reversed"
    FORCES_IN_POUNDS = "forces-in-pounds"
    FORCES_STALE = "forces-stale"
    ASYNC_SPLITS_MULTI = "async-splits-multi"
    WRIST_CONFIG_AFTER_MOTION = "wrist-config-after-motion"
    WRIST_USER_HELD_COMPLIANT = "wrist-user-held-compliant"
    OUT_OF_SYNC_IGNORED = "out-of-sync-ignored"
    GUARDS_OUTLIVE_CONNECTION = "guards-outlive-connection"
    JOINT_MOVES_STRAIGHT = "joint-moves-straight"


Kind = Literal["environment", "protocol"]


@dataclass(frozen=True)
class FaultInfo:
    """What a fault switch does."""

    fault: Fault
    kind: Kind
    description: str
    clauses: tuple[str, ...]
    argument: str | None = None
    """What ``NAME=ARG`` means, for the switches that take an argument."""

    @property
    def name(self) -> str:
        return self.fault.value


def _info(
    fault: Fault, kind: Kind, description: str, *clauses: str, argument: str | None = None
) -> tuple[Fault, FaultInfo]:
    return fault, FaultInfo(fault, kind, description, clauses, argument)


FAULTS: Final[Mapping[Fault, FaultInfo]] = MappingProxyType(
    dict(
        [
            _info(
                Fault.PANIC_BUTTON,
                "environment",
                "The panic button is pressed: arm power off, motion aborted with an asynchronous error.",
                "motion.abort",
                "motion.reset",
                "async-error.request-number",
                argument="seconds after the connection opens (default 1)",
            ),
            _info(
                Fault.OBSTACLE,
                "environment",
                "An obstacle stops one joint; moving into it is a collision (asynchronous COL error).",
                "motion.abort",
                "motion.reset",
                "async-error.request-number",
                argument="JOINT:LOWER:UPPER in degrees, either bound may be empty (e.g. 2::-60)",
            ),
            _info(
                Fault.CALIBRATE_NZI,
                "environment",
                "Calibrate finds no zero index: fatal F NZI with the joint mask, then the connection closes.",
                "calibrate.nzi",
                "error.fatal-request-number",
                "error.fatal-then-close",
                argument="joint numbers, comma separated (default 2,3)",
            ),
            _info(
                Fault.SLUGGISH_JOINT,
                "environment",
                "One joint trails its command while it moves, by more than half the collision tolerance "
                "and within it: an asynchronous warning (W COL), and the motion goes on.",
                "async-warning.format",
                "async-error.request-number",
                argument="JOINT:LAG, the joint and its lag in degrees (default 2:0.35)",
            ),
            _info(
                Fault.WRIST_SILENT,
                "environment",
                "The wrist computer stops answering (hung, or its link cut): a request that needs its "
                "data waits the wrist timeout and is answered E WNR.",
                "wrist.no-answer",
            ),
            _info(
                Fault.WRONG_REQUEST_NUMBER,
                "protocol",
                "Replies echo the request's packet number plus one.",
                "response.echoes-request-number",
            ),
            _info(
                Fault.ECHO_ACK_NUMBER,
                "protocol",
                "Replies echo the request's Chaos ack field instead of its packet number.",
                "response.echoes-request-number",
            ),
            _info(
                Fault.NO_INITIAL_RESPONSE,
                "protocol",
                "No RESPONSE is sent when the connection opens.",
                "connect.initial-response",
            ),
            _info(
                Fault.INITIAL_RESPONSE_NUMBER,
                "protocol",
                "The initial RESPONSE carries the RFC's packet number plus one.",
                "connect.initial-response-number",
            ),
            _info(
                Fault.NO_DESCRIBE_TERMINATOR,
                "protocol",
                "Describe self is not ended by an empty response packet.",
                "multi.terminated-by-empty",
                "describe.reply-shape",
            ),
            _info(
                Fault.DESCRIBE_TERMINATOR_OVERTAKEN,
                "protocol",
                "Describe self's empty terminator waits 25 servo ticks (0.4 s): a request pipelined "
                "behind describe self is answered before its reply ends.",
                "request.one-reply",
            ),
            _info(
                Fault.MULTI_WRONG_NUMBER,
                "protocol",
                "Packets of describe self after the first carry the request number plus one.",
                "multi.same-request-number",
            ),
            _info(
                Fault.NO_PROTOCOL_VERSION,
                "protocol",
                "The describe-self alist has no :protocol-version.",
                "describe.protocol-version",
            ),
            _info(
                Fault.SWAPPED_FLOAT_WORDS,
                "protocol",
                "Floats in replies are sent with their two words swapped.",
                "float.format",
            ),
            _info(
                Fault.WRONG_SEVERITY,
                "protocol",
                "Non-fatal and asynchronous errors carry severity F (and fatal errors E).",
                "error.severity-matches-opcode",
                "request.unknown-opcode",
            ),
            _info(
                Fault.ERROR_WITHOUT_COLON,
                "protocol",
                "Error strings lose the colon after where.",
                "error-string.format",
            ),
            _info(
                Fault.ERROR_PAD_MISPLACED,
                "protocol",
                "Error strings put a pad byte after the NUL even where the NUL ends at an even offset, so "
                "the numbers start at an odd one.",
                "error-string.arg-layout",
            ),
            _info(
                Fault.UOP_OPCODE_SWAPPED,
                "protocol",
                "The opcode in C UOP is sent high byte first.",
                "error-string.arg-values",
            ),
            _info(
                Fault.BDL_COUNTS_SWAPPED,
                "protocol",
                "The byte counts in C BDL are sent high byte first.",
                "error-string.arg-values",
            ),
            _info(
                Fault.JOINT_MASK_SWAPPED,
                "protocol",
                "The joint masks in JOR and TOR are sent high byte first.",
                "error-string.arg-values",
            ),
            _info(
                Fault.UNKNOWN_OPCODE_ANSWERED,
                "protocol",
                "An unknown opcode gets an empty normal response instead of C UOP.",
                "request.unknown-opcode",
            ),
            _info(
                Fault.LENGTH_UNCHECKED,
                "protocol",
                "A request with the wrong data length is cut or zero-padded and executed instead of C BDL.",
                "request.data-length",
            ),
            _info(
                Fault.EXTRA_REPLY_AFTER_ERROR,
                "protocol",
                "A non-fatal error is followed by an empty normal response to the same request.",
                "error.non-fatal-is-reply",
                "request.one-reply",
            ),
            _info(
                Fault.FATAL_WITHOUT_CLOSE,
                "protocol",
                "A fatal error leaves the connection open and the session running.",
                "error.fatal-then-close",
            ),
            _info(
                Fault.NO_JOR,
                "protocol",
                "Set joint angles accepts out-of-range joints (clamped to the limits) instead of JOR.",
                "motion.checked-before-queue",
            ),
            _info(
                Fault.SWAP_TOR_JOR,
                "protocol",
                "TOR and JOR are swapped: a transform no in-range angles reach is refused with JOR, "
                "out-of-range joint angles with TOR.",
                "solve-forwards.errors",
                "motion.checked-before-queue",
            ),
            _info(
                Fault.NO_NAP,
                "protocol",
                "Motion requests are accepted without arm power instead of NAP.",
                "motion.no-power",
            ),
            _info(
                Fault.AWA_IGNORED,
                "protocol",
                "Motion requests are accepted after an abort instead of AWA.",
                "motion.abort",
            ),
            _info(
                Fault.AWA_REFUSES_ALL,
                "protocol",
                "After an abort every request but enable power and reset abort is refused with AWA, not only "
                "motion (the E.2 table's reading, which conforms but warns; erratum awa-scope).",
                "motion.abort-serves-others",
            ),
            _info(
                Fault.SPEED_UNCHECKED,
                "protocol",
                "Set speed answers done to any factor (out-of-range ones are ignored) instead of C BVA.",
                "speed.range",
            ),
            _info(
                Fault.SEGMENT_NUMBER_STUCK,
                "protocol",
                "Every segment gets number 1.",
                "segment.number-increases",
            ),
            _info(
                Fault.UNREQUESTED_ASYNC,
                "protocol",
                "Segment-completed asynchronous responses are sent without being requested.",
                "async.only-when-requested",
            ),
            _info(
                Fault.ASYNC_STRAY_BYTE,
                "protocol",
                "Asynchronous responses carry a stray zero byte after their data: 9 bytes (7 in the 1985 "
                "guide's layout), a length neither layout has.",
                "async.layout",
            ),
            _info(
                Fault.FREE_JOINT_EXECUTES,
                "protocol",
                "The packet after free joint is executed instead of discarded with done.",
                "free-joint.awaits-next-packet",
                "free-joint.replies",
            ),
            _info(
                Fault.DESCRIBE_EXTRA_OPERATION,
                "protocol",
                "Describe self lists an opcode the server refuses as unknown (the first unassigned one).",
                "describe.operations-answered",
            ),
            _info(
                Fault.DESCRIBE_MISSING_OPERATION,
                "protocol",
                "Describe self leaves solve backwards (0221) out of :operations, though it is served.",
                "describe.operations-complete",
            ),
            _info(
                Fault.DESCRIBE_WRONG_DOF,
                "protocol",
                "Describe self states one more degree of freedom than the arm's joint vectors have.",
                "describe.dof-joint-vectors",
            ),
            _info(
                Fault.DESCRIBE_NARROW_LIMITS,
                "protocol",
                "Describe self states every joint range 5 degrees narrower at each end than the arm's.",
                "describe.joint-limits",
            ),
            _info(
                Fault.DESCRIBE_LIMITS_SHORT,
                "protocol",
                "Describe self's :joint-limits leaves out the last joint's pair (one fewer than "
                ":degrees-of-freedom).",
                "describe.joint-limits-count",
            ),
            _info(
                Fault.DESCRIBE_READY_OFF,
                "protocol",
                "Describe self states a :ready-position with joint 2 ten degrees from where move to ready "
                "goes.",
                "describe.ready-position",
            ),
            _info(
                Fault.WARNING_INTERRUPTS,
                "protocol",
                "A joint lagging its command stops the arm and aborts the motion after the warning, as a "
                "collision would.",
                "async-warning.format",
            ),
            _info(
                Fault.GUARD_HIT_WORD_SWAPPED,
                "protocol",
                "Guard-hit asynchronous responses say continue (2) for a guard that stopped the move and "
                "stop (1) for one that did not.",
                "async.layout",
            ),
            _info(
                Fault.STRAIGHT_AS_JOINT,
                "protocol",
                "Straight-line moves (205, 212) are interpolated in joint space: the hand strays off the "
                "line.",
                "straight-move.line",
            ),
            _info(
                Fault.INCREMENT_FROM_ACTUAL,
                "protocol",
                "Incremental moves add to where the arm stands when they are queued, not to where the queue "
                "ends.",
                "incremental.relative",
            ),
            _info(
                Fault.INCREMENT_O_T_SWAPPED,
                "protocol",
                "Incremental moves add dO to the pose's T angle and dT to its O angle.",
                "incremental.relative",
            ),
            _info(
                Fault.CONFIGURATION_IGNORED,
                "protocol",
                "Set configuration answers done and changes nothing: transforms are solved nearest the "
                "current angles whatever configuration was asked for.",
                "set-configuration.effect",
            ),
            _info(
                Fault.KEEPS_SPEED,
                "protocol",
                "A new connection keeps the speed factor the last one set.",
                "connect.per-connection-state",
            ),
            _info(
                Fault.KEEPS_CONFIGURATION,
                "protocol",
                "A new connection keeps the configuration (lefty or righty) the last one set.",
                "connect.per-connection-state",
            ),
            _info(
                Fault.KEEPS_NOTIFICATIONS,
                "protocol",
                "A new connection keeps the notification mask the last one asked for.",
                "connect.per-connection-state",
            ),
            _info(
                Fault.READY_LEAVES_WRIST,
                "protocol",
                "Move to ready moves joints 1-3 only: the wrist joints stay where they are.",
                "ready.pose",
            ),
            _info(
                Fault.SEGMENT_REPORT_PREVIOUS,
                "protocol",
                "Segment-completed reports name the segment queued before the one that completed.",
                "segment.fifo-completion",
            ),
            _info(
                Fault.COLLISION_UNCHECKED,
                "protocol",
                "The move process never compares the angles reached with those commanded: a blocked joint "
                "draws no error and the motion goes on.",
                "motion.collision",
            ),
            _info(
                Fault.CLOSE_KEEPS_MOVING,
                "protocol",
                "A connection that closes leaves its queued segments running, and the next connection "
                "continues its segment counter.",
                "connect.close-stops-arm",
                "connect.per-connection-state",
            ),
            _info(
                Fault.SEGMENTS_STOP,
                "protocol",
                "Queued joint segments do not blend: the arm comes to rest after each and waits 0.1 s "
                "before the next.",
                "motion.smooth-transitions",
            ),
            _info(
                Fault.SERVO_DOUBLE_RATE,
                "protocol",
                "The move process runs every 8 ms instead of 16: the angles change twice per servo cycle.",
                "motion.servo-period",
            ),
            _info(
                Fault.WRIST_TIMEOUT_SILENT,
                "protocol",
                "A request whose wrist command Cougar never answers is never answered either (no E WNR); "
                "the requests after it wait for ever.",
                "wrist.no-answer",
            ),
            _info(
                Fault.UNDERFLOW_DIRTY_ZERO,
                "protocol",
                "Reply floats below the smallest F magnitude (2^-128) are sent with exponent 0 and their "
                "fraction bits (a dirty zero) instead of a clean zero.",
                "float.dirty-zero",
            ),
            _info(
                Fault.NOT_FINITE_RESERVED,
                "protocol",
                "Solve forwards of a transform out of reach answers six angles that are not numbers, sent as "
                "the reserved operand, instead of refusing.",
                "float.not-finite",
            ),
            _info(
                Fault.FATAL_NUMBER_PREVIOUS,
                "protocol",
                "A fatal error carries the number of the request before the packet last received.",
                "error.fatal-request-number",
            ),
            _info(
                Fault.FATAL_SEVERITY_E,
                "protocol",
                "Fatal errors carry severity E (the other errors keep theirs).",
                "error.severity-matches-opcode",
            ),
            _info(
                Fault.FATAL_DROPS_LINK,
                "protocol",
                "After a fatal error the server drops the link under the connection instead of sending CLS.",
                "error.fatal-then-close",
            ),
            _info(
                Fault.ASYNC_NUMBER_PREVIOUS,
                "protocol",
                "Asynchronous errors and warnings carry the number of the request processed before the last "
                "one.",
                "async-error.request-number",
            ),
            _info(
                Fault.WRIST_ERROR_FATAL,
                "protocol",
                "A wrist request that fails (Cougar silent, its link down) is answered with a fatal error "
                "(severity F) and the connection closed, instead of a non-fatal E error.",
                "wrist.no-answer",
            ),
            _info(
                Fault.ABORT_KEEPS_QUEUE,
                "protocol",
                "An abort drops only the segment in execution: the queued ones run once motion is allowed "
                "again.",
                "motion.abort",
            ),
            _info(
                Fault.SPEED_IGNORED,
                "protocol",
                "Set speed answers done to a factor in range and changes nothing: every move runs at full "
                "speed.",
                "motion.speed-scales",
            ),
            _info(
                Fault.QUEUE_REVERSED,
                "protocol",
                "Segments queued behind the one running run newest first (each waits for the one before it "
                "to end).",
                "segment.fifo-completion",
            ),
            _info(
                Fault.WRIST_FLOAT_WORDS_SWAPPED,
                "protocol",
                "Floats in the commands the wrist processes queue for Cougar have their two words swapped.",
                "cougar.command.layout",
            ),
            _info(
                Fault.WRIST_USER_FIRST,
                "protocol",
                "The wrist output process sends the user's commands before New Position and Rate and Reset.",
                "puma.wrist.priority",
            ),
            _info(
                Fault.WRIST_NO_WAIT,
                "protocol",
                "Read forces is answered at once with the last forces seen, without waiting for Cougar.",
                "puma.wrist.waits",
            ),
            _info(
                Fault.READ_FORCES_NO_ANGLES,
                "protocol",
                "Read forces sends Report Forces without the current joint angles (SEN) before it.",
                "puma.wrist.read-forces-angles",
            ),
            _info(
                Fault.NPR_SKIPPED,
                "protocol",
                "A compliant segment sends New Position and Rate only every other servo cycle.",
                "puma.compliance.npr-every-cycle",
            ),
            _info(
                Fault.COMPLIANT_COLLISION_TEST,
                "protocol",
                "The collision test stays on under compliance.",
                "puma.compliance.no-collision-test",
            ),
            _info(
                Fault.COMPLIANT_SNAP_BACK,
                "protocol",
                "When a compliant episode ends the arm jumps back to the nominal goal.",
                "puma.compliance.segment-end",
            ),
            _info(
                Fault.GUARD_IGNORED,
                "protocol",
                "A stop-the-move guard trip is reported but the arm keeps moving.",
                "puma.guard.stop",
            ),
            _info(
                Fault.GUARD_UNREPORTED,
                "protocol",
                "Guard trips are never reported to the client.",
                "puma.guard.report",
            ),
            _info(
                Fault.CALIBRATE_ONE_POSE,
                "protocol",
                "Calibrate-wrist sets the mean of one pose's readings (gravity in them) as the offsets.",
                "puma.calibrate-wrist",
            ),
            _info(
                Fault.FATAL_EOF_WITHOUT_CLS,
                "protocol",
                "After a fatal error the server sends EOF and then drops the link under the connection "
                "before the peer's acknowledgement can draw its CLS: the connection ends with EOF, never "
                "CLS.",
                "error.fatal-then-close",
            ),
            _info(
                Fault.KEEPS_ABORT,
                "protocol",
                "A new connection keeps the abort condition the last one closed with: its first move is "
                "refused AWA.",
                "connect.per-connection-state",
            ),
            _info(
                Fault.NZI_MASK_SHIFTED,
                "protocol",
                "The joint mask of F NZI counts joints from 0 (joint n as bit n): it names the joint after "
                "each one that failed.",
                "calibrate.nzi-mask",
            ),
            _info(
                Fault.CONFIGURATION_SWAPPED,
                "protocol",
                "Set configuration reads bit 0 the wrong way round: 1 gives the righty solutions, 0 the "
                "lefty ones.",
                "set-configuration.lefty-side",
            ),
            _info(
                Fault.JOINTS_REVERSED,
                "protocol",
                "Every joint vector on the wire starts at the hand, not the base (requests, replies and "
                "describe self's limits and ready position alike): element 1 is joint 6.",
                "joint-angles.reply",
            ),
            _info(
                Fault.FORCES_IN_POUNDS,
                "protocol",
                "Read forces answers pounds and pound-inches, not ounces and ounce-inches: every component "
                "16 times too small.",
                "read-forces.units",
            ),
            _info(
                Fault.FORCES_STALE,
                "protocol",
                "Every read forces on a connection answers that connection's first reading again.",
                "read-forces.current",
            ),
            _info(
                Fault.ASYNC_SPLITS_MULTI,
                "protocol",
                "The asynchronous packets of the move and wrist processes wait for the main process's next "
                "request, and it sends them after the first packet of a multi-packet reply: describe self is "
                "split by them.",
                "multi.not-split",
            ),
            _info(
                Fault.WRIST_CONFIG_AFTER_MOTION,
                "protocol",
                "The wrist output process holds the user's commands while the arm moves: a setting reaches "
                "Cougar only once the queued segments are done.",
                "puma.wrist.config-at-once",
            ),
            _info(
                Fault.WRIST_USER_HELD_COMPLIANT,
                "protocol",
                "The wrist output process holds the user's commands during a compliant segment: read forces "
                "then times out and settings wait for the segment's end.",
                "puma.wrist.user-during-compliance",
            ),
            _info(
                Fault.OUT_OF_SYNC_IGNORED,
                "protocol",
                "Cougar's out-of-sync message is dropped: the requests waiting for Cougar wait out the wrist "
                "timeout, and the client is not warned.",
                "puma.wrist.out-of-sync",
            ),
            _info(
                Fault.GUARDS_OUTLIVE_CONNECTION,
                "protocol",
                "The guards a connection left armed on Cougar stay armed for the next connection.",
                "puma.wrist.connection-state",
            ),
            _info(
                Fault.JOINT_MOVES_STRAIGHT,
                "protocol",
                "Move and incremental move (204, 211) go along a straight line, interpolated in Cartesian "
                "space: the joints do not keep together.",
                "joint-move.interpolated",
            ),
        ]
    )
)

for _fault in Fault:
    if _fault not in FAULTS:
        raise RuntimeError(f"fault {_fault.value} has no description")
for _info_entry in FAULTS.values():
    for _clause in _info_entry.clauses:
        if _clause not in SPEC.clauses:
            raise RuntimeError(f"fault {_info_entry.name} names unknown clause {_clause!r}")

RETIRED: Final[Mapping[str, str]] = MappingProxyType(
    {
        "unaligned-error-args": "both layouts of an error string's numbers conform (erratum "
        "error-arg-layout): manip-server --error-args packed writes them straight after the NUL; the "
        "defect switch is error-pad-misplaced",
    }
)
"""Fault switches withdrawn, and what to use instead (:meth:`FaultSet.parse` says so)."""

WRIST_SIDE: Final[frozenset[Fault]] = frozenset(
    info.fault for info in FAULTS.values() if all(SPEC.clauses[c].party == "puma" for c in info.clauses)
)
"""Defects of the Puma's side of the wrist link: the server cases cannot see them (they need the suite
playing Cougar, ``manip-conform run --puma``)."""

DEFAULT_PANIC_DELAY: Final = 1.0
DEFAULT_NZI_JOINTS: Final = (2, 3)
DEFAULT_SLUGGISH: Final = Sluggish(2, 0.35)


@dataclass(frozen=True)
class FaultSet:
    """The faults a server runs with, and the arguments of the environment faults."""

    active: frozenset[Fault] = frozenset()
    panic_delay: float = DEFAULT_PANIC_DELAY
    """Seconds after the connection opens at which the panic button is pressed."""
    obstacle: Obstacle | None = None
    nzi_joints: tuple[int, ...] = DEFAULT_NZI_JOINTS
    sluggish: Sluggish = DEFAULT_SLUGGISH
    """The joint that trails its command, and by how much."""

    def __post_init__(self) -> None:
        if Fault.OBSTACLE in self.active and self.obstacle is None:
            raise ValueError("the obstacle fault needs an Obstacle")
        if not self.nzi_joints or any(not 1 <= j <= 6 for j in self.nzi_joints):
            raise ValueError("calibrate-nzi joints must be 1..6")
        if self.panic_delay < 0.0:
            raise ValueError("the panic delay must not be negative")

    def __contains__(self, fault: object) -> bool:
        return fault in self.active

    def merged(self, other: FaultSet) -> FaultSet:
        """The switches of both; the arguments of a switch ``other`` turns on are ``other``'s."""
        on = other.active
        return FaultSet(
            self.active | on,
            panic_delay=other.panic_delay if Fault.PANIC_BUTTON in on else self.panic_delay,
            obstacle=other.obstacle if Fault.OBSTACLE in on else self.obstacle,
            nzi_joints=other.nzi_joints if Fault.CALIBRATE_NZI in on else self.nzi_joints,
            sluggish=other.sluggish if Fault.SLUGGISH_JOINT in on else self.sluggish,
        )

    @classmethod
    def of(cls, *faults: Fault, obstacle: Obstacle | None = None) -> FaultSet:
        """A set of argument-free faults (and an obstacle, switched on when given)."""
        active = frozenset(faults) | ({Fault.OBSTACLE} if obstacle is not None else frozenset())
        return cls(active, obstacle=obstacle)

    @classmethod
    def parse(cls, specs: Iterable[str]) -> FaultSet:
        """Read ``NAME`` or ``NAME=ARG`` items; ValueError names the bad one."""
        out = cls()
        for spec in specs:
            name, sep, arg = spec.partition("=")
            if name.strip() in RETIRED:
                raise ValueError(f"fault {name.strip()} was withdrawn: {RETIRED[name.strip()]}")
            try:
                fault = Fault(name.strip())
            except ValueError:
                known = ", ".join(f.value for f in Fault)
                raise ValueError(f"unknown fault {name!r}; known: {known}") from None
            if sep and FAULTS[fault].argument is None:
                raise ValueError(f"fault {fault.value} takes no argument")
            try:
                out = _apply(out, fault, arg.strip() if sep else None)
            except ValueError as exc:
                raise ValueError(f"fault {fault.value}: {exc} (argument: {FAULTS[fault].argument})") from exc
        return out


def _apply(faults: FaultSet, fault: Fault, arg: str | None) -> FaultSet:
    """``faults`` with ``fault`` switched on and its argument read."""
    active = faults.active | {fault}
    if fault is Fault.PANIC_BUTTON:
        delay = DEFAULT_PANIC_DELAY if arg is None else float(arg)
        return replace(faults, active=active, panic_delay=delay)
    if fault is Fault.CALIBRATE_NZI:
        joints = DEFAULT_NZI_JOINTS if arg is None else tuple(int(j) for j in arg.split(","))
        return replace(faults, active=active, nzi_joints=joints)
    if fault is Fault.SLUGGISH_JOINT:
        if arg is None:
            return replace(faults, active=active)
        joint, sep, lag = arg.partition(":")
        if not sep:
            raise ValueError(f"{arg!r} is not JOINT:LAG")
        return replace(faults, active=active, sluggish=Sluggish(int(joint), float(lag)))
    if fault is Fault.OBSTACLE:
        if arg is None:
            raise ValueError("needs an argument")
        parts = arg.split(":")
        if len(parts) != 3:
            raise ValueError(f"{arg!r} is not JOINT:LOWER:UPPER")
        lower = float(parts[1]) if parts[1] else None
        upper = float(parts[2]) if parts[2] else None
        return replace(faults, active=active, obstacle=Obstacle(int(parts[0]), lower, upper))
    return replace(faults, active=active)
