"""Fault switches of the reference server: defects injected on purpose.

A conformance suite is only as good as the defects it catches.  Each switch here makes the reference
server break exactly one rule of the protocol.  Running the suite against the server with each switch
on, one at a time, shows whether some case catches it (mutation testing of the suite).

:class:`Fault` is the registry: each member is declared once, with one line saying what changes and the
clause ids it breaks (the record of every implementation's switches, :class:`manip.spec.faults.FaultSwitch`).
The conditions of the arm's world (the panic button, an obstacle, a calibration failure...) are not
faults: :mod:`manip.reference_server.conditions` has them, and ``--fault`` takes their names too.
:class:`FaultSet` is what a server runs with (the switches on, and the conditions its world starts in);
:meth:`FaultSet.parse` reads the ``NAME`` / ``NAME=ARG`` form a command line gives.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Final

from manip.arm.sim import Obstacle
from manip.reference_server.conditions import WorldCondition, WorldConditions
from manip.spec import SPEC
from manip.spec.faults import FaultSwitch, defect

__all__ = ["RETIRED", "WRIST_SIDE", "Fault", "FaultSet", "switch_named"]


class Fault(FaultSwitch):
    """The reference server's fault switches, each declared once."""

    # protocol defects
    WRONG_REQUEST_NUMBER = defect(
        "wrong-request-number",
        "Replies echo the request's packet number plus one.",
        "response.echoes-request-number",
        caught_by=("property.requests.well-formed",),
    )
    ECHO_ACK_NUMBER = defect(
        "echo-ack-number",
        "Replies echo the request's Chaos ack field instead of its packet number.",
        "response.echoes-request-number",
        caught_by=("property.requests.well-formed",),
    )
    NO_INITIAL_RESPONSE = defect(
        "no-initial-response",
        "No RESPONSE is sent when the connection opens.",
        "connect.initial-response",
        caught_by=("server.connect.initial-response",),
    )
    INITIAL_RESPONSE_NUMBER = defect(
        "initial-response-wrong-number",
        "The initial RESPONSE carries the RFC's packet number plus one.",
        "connect.initial-response-number",
        caught_by=("server.connect.initial-response",),
    )
    NO_DESCRIBE_TERMINATOR = defect(
        "no-describe-terminator",
        "Describe self is not ended by an empty response packet.",
        "multi.terminated-by-empty",
        "describe.reply-shape",
        caught_by=("property.requests.well-formed",),
    )
    DESCRIBE_TERMINATOR_OVERTAKEN = defect(
        "describe-terminator-overtaken",
        "Describe self's empty terminator waits 25 servo ticks (0.4 s): a request pipelined behind describe "
        "self is answered before its reply ends.",
        "request.one-reply",
        caught_by=("server.describe.pipelined",),
    )
    MULTI_WRONG_NUMBER = defect(
        "multi-wrong-number",
        "Packets of describe self after the first carry the request number plus one.",
        "multi.same-request-number",
        caught_by=("server.describe.reply-shape",),
    )
    NO_PROTOCOL_VERSION = defect(
        "no-protocol-version",
        "The describe-self alist has no :protocol-version.",
        "describe.protocol-version",
        caught_by=("server.describe.protocol-version",),
    )
    SWAPPED_FLOAT_WORDS = defect(
        "swapped-float-words",
        "Floats in replies are sent with their two words swapped.",
        "float.format",
        caught_by=("property.floats.round-trip",),
    )
    WRONG_SEVERITY = defect(
        "wrong-severity",
        "Non-fatal and asynchronous errors carry severity F (and fatal errors E).",
        "error.severity-matches-opcode",
        "request.unknown-opcode",
        caught_by=("server.error.fatal-then-close",),
    )
    ERROR_WITHOUT_COLON = defect(
        "error-without-colon",
        "Error strings lose the colon after where.",
        "error-string.format",
        caught_by=("property.requests.well-formed",),
    )
    ERROR_PAD_MISPLACED = defect(
        "error-pad-misplaced",
        "Error strings put a pad byte after the NUL even where the NUL ends at an even offset, so the "
        "numbers start at an odd one.",
        "error-string.arg-layout",
        caught_by=("server.error.arg-alignment",),
    )
    UOP_OPCODE_SWAPPED = defect(
        "uop-opcode-byte-swapped",
        "The opcode in C UOP is sent high byte first.",
        "error-string.arg-values",
        caught_by=("server.negative.unknown-opcodes",),
    )
    BDL_COUNTS_SWAPPED = defect(
        "bdl-counts-byte-swapped",
        "The byte counts in C BDL are sent high byte first.",
        "error-string.arg-values",
        caught_by=("server.negative.data-length.safe",),
    )
    JOINT_MASK_SWAPPED = defect(
        "joint-mask-byte-swapped",
        "The joint masks in JOR and TOR are sent high byte first.",
        "error-string.arg-values",
        caught_by=("server.motion.jor",),
    )
    UNKNOWN_OPCODE_ANSWERED = defect(
        "unknown-opcode-answered",
        "An unknown opcode gets an empty normal response instead of C UOP.",
        "request.unknown-opcode",
        caught_by=("server.error.severity-matches-opcode",),
    )
    LENGTH_UNCHECKED = defect(
        "length-unchecked",
        "A request with the wrong data length is cut or zero-padded and executed instead of C BDL.",
        "request.data-length",
        caught_by=("server.negative.data-length.safe",),
    )
    EXTRA_REPLY_AFTER_ERROR = defect(
        "extra-reply-after-error",
        "A non-fatal error is followed by an empty normal response to the same request.",
        "error.non-fatal-is-reply",
        "request.one-reply",
        caught_by=("server.error.non-fatal-is-reply",),
    )
    FATAL_WITHOUT_CLOSE = defect(
        "fatal-without-close",
        "A fatal error leaves the connection open and the session running.",
        "error.fatal-then-close",
        caught_by=("server.error.fatal-then-close",),
    )
    NO_JOR = defect(
        "no-jor",
        "Set joint angles accepts out-of-range joints (clamped to the limits) instead of JOR.",
        "motion.checked-before-queue",
        caught_by=("server.motion.jor",),
    )
    SWAP_TOR_JOR = defect(
        "swap-tor-jor",
        "TOR and JOR are swapped: a transform no in-range angles reach is refused with JOR, out-of-range "
        "joint angles with TOR.",
        "solve-forwards.errors",
        "motion.checked-before-queue",
        caught_by=("server.motion.jor", "server.motion.tor-limits"),
    )
    NO_NAP = defect(
        "no-nap",
        "Motion requests are accepted without arm power instead of NAP.",
        "motion.no-power",
        caught_by=("server.motion.nap",),
    )
    AWA_IGNORED = defect(
        "awa-ignored",
        "Motion requests are accepted after an abort instead of AWA.",
        "motion.abort",
        caught_by=("server.async.guard-hit",),
    )
    AWA_REFUSES_ALL = defect(
        "awa-refuses-all",
        "After an abort every request but enable power and reset abort is refused with AWA, not only motion "
        "(the E.2 table's reading, which conforms but warns; erratum awa-scope).",
        "motion.abort-serves-others",
        caught_by=("server.motion.awa-reset-abort",),
    )
    SPEED_UNCHECKED = defect(
        "speed-unchecked",
        "Set speed answers done to any factor (out-of-range ones are ignored) instead of C BVA.",
        "speed.range",
        caught_by=("server.speed.bounds",),
    )
    SEGMENT_NUMBER_STUCK = defect(
        "segment-number-stuck",
        "Every segment gets number 1.",
        "segment.number-increases",
        caught_by=("property.segments.numbering",),
    )
    UNREQUESTED_ASYNC = defect(
        "unrequested-async",
        "Segment-completed asynchronous responses are sent without being requested.",
        "async.only-when-requested",
        caught_by=("server.async.guard-hit",),
    )
    ASYNC_STRAY_BYTE = defect(
        "async-stray-byte",
        "Asynchronous responses carry a stray zero byte after their data: 9 bytes (7 in the 1985 guide's "
        "layout), a length neither layout has.",
        "async.layout",
        caught_by=("server.async.segment-completed",),
    )
    FREE_JOINT_EXECUTES = defect(
        "free-joint-executes",
        "The packet after free joint is executed instead of discarded with done.",
        "free-joint.awaits-next-packet",
        "free-joint.replies",
        caught_by=("server.free-joint.discard",),
    )
    DESCRIBE_EXTRA_OPERATION = defect(
        "describe-extra-operation",
        "Describe self lists an opcode the server refuses as unknown (the first unassigned one).",
        "describe.operations-answered",
        caught_by=("server.describe.operations-served",),
    )
    DESCRIBE_MISSING_OPERATION = defect(
        "describe-missing-operation",
        "Describe self leaves solve backwards (0221) out of :operations, though it is served.",
        "describe.operations-complete",
        caught_by=("server.describe.operations-served",),
    )
    DESCRIBE_WRONG_DOF = defect(
        "describe-wrong-dof",
        "Describe self states one more degree of freedom than the arm's joint vectors have.",
        "describe.dof-joint-vectors",
        caught_by=("server.describe.degrees-of-freedom",),
    )
    DESCRIBE_NARROW_LIMITS = defect(
        "describe-narrow-limits",
        "Describe self states every joint range 5 degrees narrower at each end than the arm's.",
        "describe.joint-limits",
        caught_by=("server.describe.joint-limits",),
    )
    DESCRIBE_LIMITS_SHORT = defect(
        "describe-limits-short",
        "Describe self's :joint-limits leaves out the last joint's pair (one fewer than "
        ":degrees-of-freedom).",
        "describe.joint-limits-count",
        caught_by=("server.describe.joint-limits",),
    )
    DESCRIBE_READY_OFF = defect(
        "describe-ready-off",
        "Describe self states a :ready-position with joint 2 ten degrees from where move to ready goes.",
        "describe.ready-position",
        caught_by=("server.motion.ready-position",),
    )
    WARNING_INTERRUPTS = defect(
        "warning-interrupts",
        "A joint lagging its command stops the arm and aborts the motion after the warning, as a collision "
        "would.",
        "async-warning.format",
        caught_by=("server.async.warning-format",),
    )
    GUARD_HIT_WORD_SWAPPED = defect(
        "guard-hit-word-swapped",
        "Guard-hit asynchronous responses say continue (2) for a guard that stopped the move and stop (1) "
        "for one that did not.",
        "async.layout",
        caught_by=("server.async.guard-hit",),
    )
    STRAIGHT_AS_JOINT = defect(
        "straight-as-joint",
        "Straight-line moves (205, 212) are interpolated in joint space: the hand strays off the line.",
        "straight-move.line",
        caught_by=("server.motion.straight-line",),
    )
    STRAIGHT_TURN_FIRST = defect(
        "straight-turn-first",
        "Straight-line moves (205, 212) turn the hand to its goal orientation over the first tenth of the "
        "line and carry it unturned the rest of the way: the position follows the line, the turn does not "
        "go with it.",
        "straight-move.orientation",
        caught_by=("server.motion.straight-line",),
    )
    INCREMENT_FROM_ACTUAL = defect(
        "increment-from-actual",
        "Incremental moves add to where the arm stands when they are queued, not to where the queue ends.",
        "incremental.relative",
        caught_by=("server.motion.incremental-reference",),
    )
    INCREMENT_O_T_SWAPPED = defect(
        "increment-o-t-swapped",
        "Incremental moves add dO to the pose's T angle and dT to its O angle.",
        "incremental.relative",
        caught_by=("server.motion.incremental-oat",),
    )
    CONFIGURATION_IGNORED = defect(
        "configuration-ignored",
        "Set configuration answers done and changes nothing: transforms are solved nearest the current "
        "angles whatever configuration was asked for.",
        "set-configuration.effect",
        caught_by=("server.motion.configuration",),
    )
    KEEPS_SPEED = defect(
        "connection-keeps-speed",
        "A new connection keeps the speed factor the last one set.",
        "connect.per-connection-state",
        caught_by=("server.connect.fresh-state",),
    )
    KEEPS_CONFIGURATION = defect(
        "connection-keeps-configuration",
        "A new connection keeps the configuration (lefty or righty) the last one set.",
        "connect.per-connection-state",
        caught_by=("server.connect.fresh-state",),
    )
    KEEPS_NOTIFICATIONS = defect(
        "connection-keeps-notifications",
        "A new connection keeps the notification mask the last one asked for.",
        "connect.per-connection-state",
        caught_by=("server.connect.fresh-state",),
    )
    READY_LEAVES_WRIST = defect(
        "ready-leaves-wrist",
        "Move to ready moves joints 1-3 only: the wrist joints stay where they are.",
        "ready.pose",
        caught_by=("server.motion.ready",),
    )
    SEGMENT_REPORT_PREVIOUS = defect(
        "segment-report-previous",
        "Segment-completed reports name the segment queued before the one that completed.",
        "segment.fifo-completion",
        caught_by=("server.motion.queued-segments",),
    )
    COLLISION_UNCHECKED = defect(
        "collision-unchecked",
        "The move process never compares the angles reached with those commanded: a blocked joint draws no "
        "error and the motion goes on.",
        "motion.collision",
        caught_by=("server.motion.collision",),
    )
    CLOSE_KEEPS_MOVING = defect(
        "close-keeps-moving",
        "A connection that closes leaves its queued segments running, and the next connection continues its "
        "segment counter.",
        "connect.close-stops-arm",
        "connect.per-connection-state",
        caught_by=("server.connect.close-stops-arm",),
    )
    SEGMENTS_STOP = defect(
        "segments-stop",
        "Queued joint segments do not blend: the arm comes to rest after each and waits 0.1 s before the "
        "next.",
        "motion.smooth-transitions",
        caught_by=("server.motion.queued-segments",),
    )
    SERVO_DOUBLE_RATE = defect(
        "servo-double-rate",
        "The move process runs every 8 ms instead of 16: the angles change twice per servo cycle.",
        "motion.servo-period",
        caught_by=("server.motion.queued-segments",),
    )
    WRIST_TIMEOUT_SILENT = defect(
        "wrist-timeout-silent",
        "A request whose wrist command Cougar never answers is never answered either (no E WNR); the "
        "requests after it wait for ever.",
        "wrist.no-answer",
        caught_by=("server.wrist.no-answer",),
    )
    UNDERFLOW_CLAMPED = defect(
        "underflow-clamped",
        "Reply floats below the smallest F magnitude (2^-128) are sent as plus or minus 2^-128 (the encoder "
        "clamps the exponent at its least) instead of zero.",
        "float.range",
        caught_by=("server.float.extremes",),
    )
    UNDERFLOW_DIRTY_ZERO = defect(
        "underflow-dirty-zero",
        "Reply floats below the smallest F magnitude (2^-128) are sent with exponent 0 and their fraction "
        "bits (a dirty zero) instead of a clean zero.",
        "float.dirty-zero",
        caught_by=("server.float.extremes",),
    )
    NOT_FINITE_RESERVED = defect(
        "not-finite-reserved",
        "Solve forwards of a transform out of reach answers six angles that are not numbers, sent as the "
        "reserved operand, instead of refusing.",
        "float.not-finite",
        caught_by=("server.float.extremes",),
    )
    FATAL_NUMBER_PREVIOUS = defect(
        "fatal-number-previous",
        "A fatal error carries the number of the request before the packet last received.",
        "error.fatal-request-number",
        caught_by=("server.error.fatal-then-close",),
    )
    FATAL_SEVERITY_E = defect(
        "fatal-severity-e",
        "Fatal errors carry severity E (the other errors keep theirs).",
        "error.severity-matches-opcode",
        caught_by=("server.error.fatal-then-close",),
    )
    FATAL_DROPS_LINK = defect(
        "fatal-drops-link",
        "After a fatal error the server drops the link under the connection instead of sending CLS.",
        "error.fatal-then-close",
        caught_by=("server.error.fatal-then-close",),
    )
    ASYNC_NUMBER_PREVIOUS = defect(
        "async-number-previous",
        "Asynchronous errors and warnings carry the number of the request processed before the last one.",
        "async-error.request-number",
        caught_by=("server.async.warning-format",),
    )
    WRIST_ERROR_FATAL = defect(
        "wrist-error-fatal",
        "A wrist request that fails (Cougar silent, its link down) is answered with a fatal error (severity "
        "F) and the connection closed, instead of a non-fatal E error.",
        "wrist.no-answer",
        caught_by=("server.wrist.no-answer",),
    )
    ABORT_KEEPS_QUEUE = defect(
        "abort-keeps-queue",
        "An abort drops only the segment in execution: the queued ones run once motion is allowed again.",
        "motion.abort",
        caught_by=("server.motion.abort-drops-queue",),
    )
    SPEED_IGNORED = defect(
        "speed-ignored",
        "Set speed answers done to a factor in range and changes nothing: every move runs at full speed.",
        "motion.speed-scales",
        caught_by=("server.speed.scales",),
    )
    QUEUE_REVERSED = defect(
        "queue-reversed",
        "Segments queued behind the one running run newest first (each waits for the one before it to end).",
        "segment.fifo-completion",
        caught_by=("server.motion.queued-segments",),
    )
    # protocol defects of the Puma's side of the wrist link (judged by manip-conform run --puma)
    WRIST_FLOAT_WORDS_SWAPPED = defect(
        "wrist-float-words-swapped",
        "Floats in the commands the wrist processes queue for Cougar have their two words swapped.",
        "cougar.command.layout",
        caught_by=("puma.wrist.command-layout",),
    )
    WRIST_USER_FIRST = defect(
        "wrist-user-first",
        "The wrist output process sends the user's commands before New Position and Rate and Reset.",
        "puma.wrist.priority",
        caught_by=("puma.wrist.priority",),
    )
    WRIST_NO_WAIT = defect(
        "wrist-no-wait",
        "Read forces is answered at once with the last forces seen, without waiting for Cougar.",
        "puma.wrist.waits",
        caught_by=("puma.wrist.waits",),
    )
    READ_FORCES_NO_ANGLES = defect(
        "read-forces-no-angles",
        "Read forces sends Report Forces without the current joint angles (SEN) before it.",
        "puma.wrist.read-forces-angles",
        caught_by=("puma.wrist.read-forces-angles",),
    )
    NPR_SKIPPED = defect(
        "npr-skipped",
        "A compliant segment sends New Position and Rate only every other servo cycle.",
        "puma.compliance.npr-every-cycle",
        caught_by=("puma.compliance.npr-every-cycle",),
    )
    COMPLIANT_COLLISION_TEST = defect(
        "compliant-collision-test",
        "The collision test stays on under compliance.",
        "puma.compliance.no-collision-test",
        caught_by=("puma.compliance.no-collision-test",),
    )
    COMPLIANT_SNAP_BACK = defect(
        "compliant-snap-back",
        "When a compliant episode ends the arm jumps back to the nominal goal.",
        "puma.compliance.segment-end",
        caught_by=("puma.compliance.segment-end",),
    )
    GUARD_IGNORED = defect(
        "guard-ignored",
        "A stop-the-move guard trip is reported but the arm keeps moving.",
        "puma.guard.stop",
        caught_by=("puma.guard.stop",),
    )
    GUARD_UNREPORTED = defect(
        "guard-unreported",
        "Guard trips are never reported to the client.",
        "puma.guard.report",
        caught_by=("puma.guard.report",),
    )
    CALIBRATE_ONE_POSE = defect(
        "calibrate-one-pose",
        "Calibrate-wrist sets the mean of one pose's readings (gravity in them) as the offsets.",
        "puma.calibrate-wrist",
        caught_by=("puma.calibrate-wrist",),
    )
    # protocol defects found from outside (issue 32)
    FATAL_EOF_WITHOUT_CLS = defect(
        "fatal-eof-without-cls",
        "After a fatal error the server sends EOF and then drops the link under the connection before the "
        "peer's acknowledgement can draw its CLS: the connection ends with EOF, never CLS.",
        "error.fatal-then-close",
        caught_by=("server.error.fatal-then-close",),
    )
    KEEPS_ABORT = defect(
        "connection-keeps-abort",
        "A new connection keeps the abort condition the last one closed with: its first move is refused AWA.",
        "connect.per-connection-state",
        caught_by=("server.connect.abort-not-carried",),
    )
    NZI_MASK_SHIFTED = defect(
        "nzi-mask-shifted",
        "The joint mask of F NZI counts joints from 0 (joint n as bit n): it names the joint after each one "
        "that failed.",
        "calibrate.nzi-mask",
        caught_by=("server.error.fatal-then-close",),
    )
    CONFIGURATION_SWAPPED = defect(
        "configuration-swapped",
        "Set configuration reads bit 0 the wrong way round: 1 gives the righty solutions, 0 the lefty ones.",
        "set-configuration.lefty-side",
        caught_by=("server.motion.configuration-side",),
    )
    JOINTS_REVERSED = defect(
        "joints-reversed",
        "Every joint vector on the wire starts at the hand, not the base (requests, replies and describe "
        "self's limits and ready position alike): element 1 is joint 6.",
        "joint-angles.reply",
        caught_by=("server.motion.joint-order",),
    )
    FORCES_IN_POUNDS = defect(
        "forces-in-pounds",
        "Read forces answers pounds and pound-inches, not ounces and ounce-inches: every component 16 times "
        "too small.",
        "read-forces.units",
        caught_by=("server.async.guard-hit",),
    )
    FORCES_STALE = defect(
        "forces-stale",
        "Every read forces on a connection answers that connection's first reading again.",
        "read-forces.current",
        caught_by=("server.wrist.force-push",),
    )
    ASYNC_SPLITS_MULTI = defect(
        "async-splits-multi",
        "The asynchronous packets of the move and wrist processes wait for the main process's next request, "
        "and it sends them after the first packet of a multi-packet reply: describe self is split by them.",
        "multi.not-split",
        caught_by=("server.describe.not-split",),
    )
    WRIST_CONFIG_AFTER_MOTION = defect(
        "wrist-config-after-motion",
        "The wrist output process holds the user's commands while the arm moves: a setting reaches Cougar "
        "only once the queued segments are done.",
        "puma.wrist.config-at-once",
        caught_by=("puma.wrist.config-at-once",),
    )
    WRIST_USER_HELD_COMPLIANT = defect(
        "wrist-user-held-compliant",
        "The wrist output process holds the user's commands during a compliant segment: read forces then "
        "times out and settings wait for the segment's end.",
        "puma.wrist.user-during-compliance",
        caught_by=("puma.wrist.user-during-compliance",),
    )
    OUT_OF_SYNC_IGNORED = defect(
        "out-of-sync-ignored",
        "Cougar's out-of-sync message is dropped: the requests waiting for Cougar wait out the wrist "
        "timeout, and the client is not warned.",
        "puma.wrist.out-of-sync",
        caught_by=("puma.wrist.out-of-sync",),
    )
    GUARDS_OUTLIVE_CONNECTION = defect(
        "guards-outlive-connection",
        "The guards a connection left armed on Cougar stay armed for the next connection.",
        "puma.wrist.connection-state",
        caught_by=("puma.wrist.connection-state",),
    )
    COMPLIANT_NOMINAL_IGNORED = defect(
        "compliant-nominal-ignored",
        "A compliant segment leaves out its nominal path: the arm stays where the segment began, moved only "
        "by Cougar's New Theta Dot corrections, and rests there when the segment ends.",
        "puma.compliance.nominal-path",
        caught_by=("puma.compliance.nominal-path",),
    )
    WRIST_USER_BEFORE_MOVE_QUEUE = defect(
        "wrist-user-before-move-queue",
        "The wrist output process sends the user's commands before the move process's wrist packets (the "
        "sensed angles it queues while the arm moves); New Position and Rate and Reset still go first.",
        "puma.wrist.priority",
        caught_by=("puma.wrist.move-queue-first",),
    )
    JOINT_MOVES_STRAIGHT = defect(
        "joint-moves-straight",
        "Move and incremental move (204, 211) go along a straight line, interpolated in Cartesian space: "
        "the joints do not keep together.",
        "joint-move.interpolated",
        caught_by=("server.motion.joint-interpolated",),
    )
    # protocol defects proving the clauses no fault proved (issue 32)
    CALIBRATE_REPLIES_MASK = defect(
        "calibrate-replies-mask",
        "Calibrate answers done with a word after the request number: the mask of the joints that found "
        "their zero index.",
        "calibrate.done",
        "response.done-empty",
        caught_by=("server.reply.calibrate",),
    )
    NZI_MASK_IN_TEXT = defect(
        "nzi-mask-in-text",
        'F NZI names the joints that failed in its text ("joints 2 5"), with no NUL and no $ mask argument.',
        "calibrate.nzi",
        "calibrate.nzi-mask",
        caught_by=("server.error.fatal-then-close",),
    )
    KILL_POWER_REPLIES_STATE = defect(
        "kill-power-replies-state",
        "Kill power answers done with a word after the request number: arm power as it now is (0, off).",
        "kill-power.done",
        "response.done-empty",
        caught_by=("server.reply.kill-power", "server.motion.nap"),
    )
    ENABLE_POWER_REPLIES_STATE = defect(
        "enable-power-replies-state",
        "Enable high power answers done with a word after the request number: arm power as it now is "
        "(1, on).",
        "enable-power.done",
        "response.done-empty",
        caught_by=("server.reply.enable-power",),
    )
    SET_CONFIGURATION_WORD_ONLY = defect(
        "set-configuration-word-only",
        "Set configuration takes a word only: one data byte, which the 1985 guide allows, is refused with "
        "C BDL.",
        "set-configuration.data",
        caught_by=("server.negative.set-configuration-sizes",),
    )
    HAND_FLAG_ONLY = defect(
        "hand-flag-only",
        "Open or close hand refuses any amount but 0 and 1 with C BVA, as if the word were a flag.",
        "hand.data",
        caught_by=("server.hand.amounts",),
    )
    INCREMENT_ANGLES_FIRST = defect(
        "increment-angles-first",
        "Incremental moves (211, 212) read their six floats as dO dA dT dX dY dZ: the angles first.",
        "incremental-move.data",
        "incremental-straight-move.data",
        caught_by=("server.motion.incremental-oat",),
    )
    FREE_JOINT_FROM_ZERO = defect(
        "free-joint-from-zero",
        "Free joint counts joints from 0: 0 frees joint 1, 5 frees joint 6, and 6 is refused.",
        "free-joint.data",
        caught_by=("server.free-joint.bad-joint",),
    )
    MOTION_REPLY_AT_REST = defect(
        "motion-reply-at-rest",
        "The main process waits for the arm: a motion request's reply, and every reply after it, is held "
        "until the arm comes to rest.",
        "motion.reply-before-motion",
        caught_by=("server.motion.reply-before-motion",),
    )
    POWER_KEEPS_ABORT = defect(
        "power-keeps-abort",
        "Enable high power restores arm power but leaves an abort in force: only Reset abort clears AWA.",
        "motion.reset",
        caught_by=("server.motion.awa-reset-by-power",),
    )
    ASYNC_CODES_FROM_BITS = defect(
        "async-codes-from-bits",
        "Asynchronous responses carry their condition's request-notifications bit as its code: guard hit 0, "
        "segment completed 1.",
        "async.codes",
        caught_by=("server.async.segment-completed",),
    )
    CALIBRATE_STAYS_AWAY = defect(
        "calibrate-stays-away",
        "Calibrate wrist answers with the arm left at its second calibration pose: it never moves back to "
        "where it started.",
        "puma.calibrate-wrist.positions",
        caught_by=("puma.calibrate-wrist.positions",),
    )
    COMMAND_LEAD = defect(
        "command-lead",
        "The move process adds four servo cycles of the path's velocity to each command: the arm runs ahead "
        "of its path, and passes a goal with nothing queued after it before it settles there.",
        "motion.ends-at-rest",
        caught_by=("server.motion.queued-segments",),
    )
    SECOND_CLIENT_ADMITTED = defect(
        "second-client-admitted",
        "A second connection while one is open is accepted, with a session of its own on the one robot.",
        "connect.one-server-per-robot",
        caught_by=("server.connect.one-server-per-robot",),
    )
    # protocol defects of the wire's layouts: the replies, describe self, error strings (issue 32)
    RESERVED_FLOAT_AS_ZERO = defect(
        "reserved-float-as-zero",
        "A reserved-operand float in a request is read as zero (a decoder that looks at the exponent only) "
        "and the request is executed, instead of refused with C BFL.",
        "request.reserved-float",
        caught_by=("server.negative.reserved-float.safe",),
    )
    REQUEST_NUMBER_HIGH_FIRST = defect(
        "request-number-high-byte-first",
        "Replies and errors carry the request number high byte first (a big-endian host's own order).",
        "response.word-byte-order",
        caught_by=("server.reply.here",),
    )
    DATA_REPLIES_DWD = defect(
        "data-replies-dwd",
        "Data replies (here, joint angles, the solutions, the wrist's readings) go out with Chaos opcode "
        "0300 (DWD, word data: their data are words and floats) instead of RESPONSE (0200).",
        "response.server-opcodes",
        caught_by=("server.reply.here",),
    )
    DONE_WITH_WORD = defect(
        "done-with-zero-word",
        "A simple done carries a zero word after the request number (the segment replies' layout used for "
        "every reply).",
        "response.done-empty",
        caught_by=("server.reply.enable-power",),
    )
    DATA_LENGTH_WORD = defect(
        "data-length-word",
        "Data replies carry a word giving their data's length in bytes before the data.",
        "response.data-layout",
        caught_by=("server.reply.joint-angles",),
    )
    MOTION_REPLY_DONE = defect(
        "motion-reply-done",
        "Motion requests are answered with an empty done (E.1's 'The response is a done' read alone), "
        "without the segment number.",
        "response.segment-number",
        caught_by=("server.reply.move",),
    )
    DESCRIBE_DONE = defect(
        "describe-self-done",
        "Describe self is answered by a bare done (an empty RESPONSE): no text packet before it.",
        "describe.reply-shape",
        caught_by=("server.describe.reply-shape",),
    )
    DESCRIBE_UNCLOSED = defect(
        "describe-unclosed",
        "The describe-self alist is never closed: its last parenthesis is left out.",
        "describe.alist-readable",
        caught_by=("server.describe.alist",),
    )
    DESCRIBE_KEY_TWICE = defect(
        "describe-key-twice",
        "Describe self states :software-version twice: its modules' versions, then the server's own number.",
        "describe.alist-shape",
        caught_by=("server.describe.alist",),
    )
    DESCRIBE_DECIMAL = defect(
        "describe-decimal",
        "Describe self prints its numbers in decimal without the trailing point (opcodes 128 to 177).",
        "describe.numbers-octal",
        caught_by=("server.describe.alist",),
    )
    DESCRIBE_BRAND_SYMBOL = defect(
        "describe-brand-symbol",
        ":brand-name is written without its double quotes, as a symbol (UNIMATION-PUMA-600).",
        "describe.brand-name",
        caught_by=("server.describe.keys",),
    )
    DESCRIBE_UNIQUE_NUMBER = defect(
        "describe-unique-number",
        ":unique-name is the robot's serial number, written as a number, not a string.",
        "describe.unique-name",
        caught_by=("server.describe.keys",),
    )
    DESCRIBE_DOF_STRING = defect(
        "describe-dof-string",
        ':degrees-of-freedom is written as a string ("6"), not a number.',
        "describe.degrees-of-freedom",
        caught_by=("server.describe.keys",),
    )
    DESCRIBE_OPERATION_NAMES = defect(
        "describe-operation-names",
        ":operations lists the operations by name (DESCRIBE-SELF HERE ...), not by opcode.",
        "describe.operations",
        caught_by=("server.describe.keys",),
    )
    WHERE_WITH_COLON = defect(
        "where-with-colon",
        "The where part of error strings names the server and its handler with a colon between "
        "(PUMA:dispatch).",
        "error-string.where-no-colon",
        caught_by=("server.error.string-format",),
    )
    SEVERITY_LOWER_CASE = defect(
        "severity-lower-case",
        "Error strings carry their severity in lower case (c, e, f, w, bf, be).",
        "error-string.severity",
        caught_by=("server.error.string-format",),
    )
    ERROR_CODE_NUMBERS = defect(
        "error-code-numbers",
        "Error strings carry the error's number (its place in the server's table, three octal digits) "
        "instead of its three-letter code.",
        "error-string.code",
        caught_by=("server.error.string-format",),
    )
    ERROR_ARGS_BYTES = defect(
        "error-args-bytes",
        "The numbers after an error string's NUL are single bytes (as the 1985 guide's NZI example calls its "
        "joint mask), not 16-bit words.",
        "error-string.args",
        caught_by=("server.error.string-format",),
    )
    HERE_ROW_MAJOR = defect(
        "here-row-major",
        "Here sends its transform row by row (Nx Ox Ax Px Ny ...), not in column-major order.",
        "here.transform",
        caught_by=("server.float.here-consistent",),
    )
    SOLVE_FORWARDS_RADIANS = defect(
        "solve-forwards-radians",
        "Solve forwards answers its six angles in radians, as its kinematics computes them, not degrees.",
        "solve-forwards.data",
        caught_by=("server.float.solve-round-trip",),
    )
    SOLVE_BACKWARDS_RADIANS = defect(
        "solve-backwards-radians",
        "Solve backwards reads its six angles as radians, not degrees.",
        "solve-backwards.data",
        caught_by=("server.float.here-consistent",),
    )

    # protocol defects of the Chaos level: the NCP and the link framings (issue 32)
    LOS_UNKNOWN_IGNORED = defect(
        "no-los-unknown-connection",
        "A packet for a connection that does not exist is dropped without a LOS.",
        "ncp.los",
        caught_by=("server.ncp.los-unknown-connection",),
    )
    ILLEGAL_OPCODE_IGNORED = defect(
        "illegal-opcode-ignored",
        "A packet with an illegal opcode (017-0177) is dropped without a LOS.",
        "chaos.opcode.legal",
        "ncp.los",
        caught_by=("server.ncp.los-illegal-opcode",),
    )
    OVERSIZE_SERVED = defect(
        "oversize-served",
        "Neither the link nor the NCP bounds a packet's data at 488 bytes: a frame carrying more is taken, "
        "and its packet delivered, without a LOS.",
        "chaos.data.max-488",
        "ncp.los",
        caught_by=("server.negative.oversize-frame",),
    )
    NO_RETRANSMISSION = defect(
        "no-retransmission",
        "Controlled packets are sent once: a packet no receipt covers is never sent again.",
        "ncp.retransmission",
        caught_by=("server.ncp.retransmission",),
    )
    DUPLICATE_RFC_NEW = defect(
        "duplicate-rfc-new",
        "A retransmitted RFC (same host and index) is taken as a new request, not matched to the connection "
        "it opened: it is refused, the robot being taken.",
        "ncp.duplicate-rfc",
        caught_by=("server.ncp.duplicate-rfc",),
    )
    SILENT_PEER_KEPT = defect(
        "silent-peer-kept",
        "A connection whose peer falls silent is never declared broken: it keeps the robot for ever.",
        "ncp.broken",
        caught_by=("server.ncp.broken",),
    )
    PACKET_NUMBERS_SKIP = defect(
        "packet-numbers-skip",
        "Each data packet is numbered two after the one before (the counter advanced when the packet is "
        "queued and again when it is sent): the peer waits for ever for the numbers skipped.",
        "ncp.packet-numbers",
        caught_by=("server.link.packet-numbers",),
    )
    HEADER_SOURCE_FIRST = defect(
        "header-source-first",
        "The header's source host and index words come before the destination's: every packet names the "
        "server's peer as its source.",
        "chaos.header.layout",
        caught_by=("server.link.tcp-frames",),
    )
    HEADER_LOW_BYTE_SET = defect(
        "header-low-byte-set",
        "The byte below the opcode in header word 0 is sent as 1, not zero.",
        "chaos.header.unused-byte-zero",
        caught_by=("server.link.tcp-frames",),
    )
    NBYTES_WHOLE_WORDS = defect(
        "nbytes-whole-words",
        "nbytes counts the data in whole words: an odd last data byte is sent but not counted.",
        "chaos.header.nbytes",
        caught_by=("server.link.tcp-frames",),
    )
    DATA_BYTES_SWAPPED = defect(
        "data-bytes-swapped",
        "The data go out with the first byte of each word in its high byte, not its low one: the "
        "request numbers the replies quote, like everything else, are byte-swapped.",
        "chaos.data.byte-order",
        caught_by=("server.link.tcp-frames",),
    )
    TCP_LENGTH_UNPADDED = defect(
        "tcp-length-unpadded",
        "The TCP link's frame length leaves out the pad byte after an odd last data byte (the pad itself is "
        "sent): the first such frame has an odd length, and the stream its frames can no longer be found in.",
        "link.tcp.framing",
        caught_by=("server.link.tcp-frames",),
    )
    CHUDP_NO_HEADER = defect(
        "chudp-no-header",
        "CHUDP datagrams are sent without their 4-byte header 01 01 00 00: the packet and trailer alone.",
        "chudp.header",
        caught_by=("server.link.chudp-frames",),
    )
    CHUDP_ODD_BYTE_UNPADDED = defect(
        "chudp-odd-byte-unpadded",
        "On CHUDP an odd last data byte is sent alone, without the zero byte that makes its word whole.",
        "chudp.length",
        caught_by=("server.link.chudp-frames",),
    )
    CHUDP_LSB_FIRST = defect(
        "chudp-lsb-first",
        "CHUDP words are sent least significant byte first (as the comment of klh10's dpchaos.c has it).",
        "chudp.word-order",
        caught_by=("server.link.chudp-frames",),
    )
    TRAILER_SOURCE_DESTINATION = defect(
        "trailer-source-destination",
        "The trailer's hardware source names the next hop (the hardware destination) instead of the "
        "sender's own address.",
        "chudp.trailer",
        caught_by=("server.link.chudp-frames",),
    )
    CHECKSUM_WITHOUT_TRAILER = defect(
        "checksum-without-trailer",
        "The checksum is taken over the header and data only, leaving out the trailer's two address words.",
        "chudp.checksum",
        caught_by=("server.link.chudp-frames",),
    )
    CHAOSD_MSB_FIRST = defect(
        "chaosd-msb-first",
        "On the chaosd socket the words are sent most significant byte first, as on CHUDP, not low byte "
        "first.",
        "link.chaosd.framing",
        caught_by=("server.link.chaosd-frames",),
    )


RETIRED: Final[Mapping[str, str]] = MappingProxyType(
    {
        "unaligned-error-args": "both layouts of an error string's numbers conform (erratum "
        "error-arg-layout): manip-server --error-args packed writes them straight after the NUL; the "
        "defect switch is error-pad-misplaced",
    }
)
"""Fault switches withdrawn, and what to use instead (:meth:`FaultSet.parse` says so)."""

WRIST_SIDE: Final[frozenset[Fault]] = frozenset(
    fault for fault in Fault if all(SPEC.clauses[c].party == "puma" for c in fault.clauses)
)
"""Defects of the Puma's side of the wrist link: the server cases cannot see them (they need the suite
playing Cougar, ``manip-conform run --puma``)."""


def switch_named(name: str) -> Fault | WorldCondition:
    """The fault switch or world condition ``--fault NAME`` names; ValueError naming the known ones."""
    if name in RETIRED:
        raise ValueError(f"fault {name} was withdrawn: {RETIRED[name]}")
    for kind in (WorldCondition, Fault):
        for member in kind:
            if member.value == name:
                return member
    known = ", ".join([*(c.value for c in WorldCondition), *(f.value for f in Fault)])
    raise ValueError(f"unknown fault {name!r}; known: {known}")


@dataclass(frozen=True)
class FaultSet:
    """What a server runs with: the fault switches on, and the conditions of the world it starts in."""

    active: frozenset[Fault] = frozenset()
    world: WorldConditions = field(default_factory=WorldConditions)

    def __contains__(self, switch: object) -> bool:
        return switch in self.active or switch in self.world

    def merged(self, other: FaultSet) -> FaultSet:
        """The switches and conditions of both; the arguments of a condition ``other`` has are ``other``'s."""
        return FaultSet(self.active | other.active, self.world.merged(other.world))

    @classmethod
    def of(cls, *faults: Fault, obstacle: Obstacle | None = None) -> FaultSet:
        """A set of fault switches (and an obstacle in the arm's way, when given)."""
        world = (
            WorldConditions()
            if obstacle is None
            else WorldConditions(frozenset({WorldCondition.OBSTACLE}), obstacle=obstacle)
        )
        return cls(frozenset(faults), world)

    @classmethod
    def parse(cls, specs: Iterable[str]) -> FaultSet:
        """Read ``NAME`` or ``NAME=ARG`` items (fault switches and world conditions); ValueError names
        the bad one."""
        active: set[Fault] = set()
        world = WorldConditions()
        for spec in specs:
            name, sep, arg = spec.partition("=")
            switch = switch_named(name.strip())
            if isinstance(switch, Fault):
                if sep:
                    raise ValueError(f"fault {switch.value} takes no argument")
                active.add(switch)
                continue
            if sep and switch.argument is None:
                raise ValueError(f"fault {switch.value} takes no argument")
            try:
                world = world.with_condition(switch, arg.strip() if sep else None)
            except ValueError as exc:
                raise ValueError(f"fault {switch.value}: {exc} (argument: {switch.argument})") from exc
        return cls(frozenset(active), world)
