"""Named constants generated from the spec data (``manip/spec/data/*.toml``).

DO NOT EDIT: regenerate with ``python tools/gen_constants.py``; a test checks this file is current.
"""

from enum import IntEnum
from typing import Final, Literal


class ChaosOp(IntEnum):
    """Chaosnet packet opcodes."""

    RFC = 0o1
    OPN = 0o2
    CLS = 0o3
    FWD = 0o4
    ANS = 0o5
    SNS = 0o6
    STS = 0o7
    RUT = 0o10
    LOS = 0o11
    LSN = 0o12
    MNT = 0o13
    EOF = 0o14
    UNC = 0o15
    BRD = 0o16
    DAT = 0o200
    DWD = 0o300


class RequestOp(IntEnum):
    """Chaos manipulator protocol request opcodes (Puma extensions included)."""

    DESCRIBE_SELF = 0o200
    HERE = 0o201
    JOINT_ANGLES = 0o202
    CALIBRATE = 0o203
    MOVE = 0o204
    STRAIGHT_MOVE = 0o205
    KILL_POWER = 0o206
    SET_CONFIGURATION = 0o207
    HAND = 0o210
    INCREMENTAL_MOVE = 0o211
    INCREMENTAL_STRAIGHT_MOVE = 0o212
    FREE_JOINT = 0o213
    READY = 0o214
    SET_JOINT_ANGLES = 0o215
    SET_SPEED = 0o216
    ENABLE_POWER = 0o217
    SOLVE_FORWARDS = 0o220
    SOLVE_BACKWARDS = 0o221
    READ_FORCES = 0o240
    READ_RAW_GAUGES = 0o241
    SET_GAUGE_OFFSETS = 0o242
    CALIBRATE_WRIST = 0o243
    SET_SPRING = 0o244
    SET_DAMPING = 0o245
    SET_JOINT_DAMPING = 0o246
    SET_FRAME_VECTOR = 0o247
    SET_WEIGHT = 0o250
    SET_GUARD = 0o251
    CLEAR_GUARD = 0o252
    COMPLIANT_MOVE = 0o253
    EXAMINE_WRIST = 0o254
    DEPOSIT_WRIST = 0o255
    WRIST_VERSION = 0o256
    REQUEST_NOTIFICATIONS = 0o257
    RESET_ABORT = 0o260
    SET_COMMANDED_FORCE = 0o261


class ServerOp(IntEnum):
    """Opcodes of packets sent by the server."""

    RESPONSE = 0o200
    FATAL_ERROR = 0o201
    NON_FATAL_ERROR = 0o202
    ASYNCHRONOUS_RESPONSE = 0o203
    ASYNCHRONOUS_ERROR = 0o204
    ASYNCHRONOUS_WARNING = 0o205


class AsyncCondition(IntEnum):
    """Condition codes of asynchronous responses (0203)."""

    GUARD_HIT = 1
    SEGMENT_COMPLETED = 2


class CougarCommand(IntEnum):
    """Puma-to-Cougar command codes (Table 1)."""

    NOP = 0
    WINIT = 1
    SEN = 2
    FINIT = 3
    NPR = 4
    NFC = 5
    NK = 6
    NB = 7
    NBJI = 8
    NFV = 9
    RST = 10
    DPST = 11
    EXMN = 12
    VERS = 13
    RFRC = 14
    NEWWC = 15
    GUARDS = 16
    GUARDC = 17
    RRAW = 18
    WGOV = 19


class CougarResponse(IntEnum):
    """Cougar-to-Puma response codes (Table 1)."""

    NTD = 1
    OUT_OF_SYNC = 2
    EXMN_DATA = 4
    FORCES = 5
    GUARD_STOP = 6
    GUARD_CONTINUE = 7
    VERSION = 8
    RAW = 9


RequestName = Literal[
    "describe-self",
    "here",
    "joint-angles",
    "calibrate",
    "move",
    "straight-move",
    "kill-power",
    "set-configuration",
    "hand",
    "incremental-move",
    "incremental-straight-move",
    "free-joint",
    "ready",
    "set-joint-angles",
    "set-speed",
    "enable-power",
    "solve-forwards",
    "solve-backwards",
    "read-forces",
    "read-raw-gauges",
    "set-gauge-offsets",
    "calibrate-wrist",
    "set-spring",
    "set-damping",
    "set-joint-damping",
    "set-frame-vector",
    "set-weight",
    "set-guard",
    "clear-guard",
    "compliant-move",
    "examine-wrist",
    "deposit-wrist",
    "wrist-version",
    "request-notifications",
    "reset-abort",
    "set-commanded-force",
]
"""Every request opcode's name: a misspelt operation name is a type error."""


ANSWER_OPS: Final[frozenset[ServerOp]] = frozenset(
    {
        ServerOp.RESPONSE,
        ServerOp.FATAL_ERROR,
        ServerOp.NON_FATAL_ERROR,
    }
)
"""Server opcodes that answer a request."""


ASYNC_OPS: Final[frozenset[ServerOp]] = frozenset(
    {
        ServerOp.ASYNCHRONOUS_RESPONSE,
        ServerOp.ASYNCHRONOUS_ERROR,
        ServerOp.ASYNCHRONOUS_WARNING,
    }
)
"""Server opcodes sent unasked, between replies."""


ERROR_STRING_OPS: Final[frozenset[ServerOp]] = frozenset(
    {
        ServerOp.FATAL_ERROR,
        ServerOp.NON_FATAL_ERROR,
        ServerOp.ASYNCHRONOUS_ERROR,
        ServerOp.ASYNCHRONOUS_WARNING,
    }
)
"""Server opcodes whose data is a request number and an error string (the severities' opcodes)."""


ERROR_REPLY_OPS: Final[frozenset[ServerOp]] = frozenset(
    {
        ServerOp.FATAL_ERROR,
        ServerOp.NON_FATAL_ERROR,
    }
)
"""Server opcodes that answer a request with an error string."""


ASYNC_ERROR_OPS: Final[frozenset[ServerOp]] = frozenset(
    {
        ServerOp.ASYNCHRONOUS_ERROR,
        ServerOp.ASYNCHRONOUS_WARNING,
    }
)
"""Server opcodes sent unasked with an error string (which quote the last request processed)."""
