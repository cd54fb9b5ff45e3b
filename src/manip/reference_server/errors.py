"""Error strings of the reference server, all in the 1985 guide's ``where: severity code message`` form.

Handlers raise :class:`RequestError` with the :class:`~manip.codecs.error_string.ErrorMessage` to answer.
Refusals of the simulated arm (:class:`~manip.arm.sim.Refused`, which knows only the error code) and
its asynchronous events are turned into error strings here, so every text the server sends is in one
place.
"""

from __future__ import annotations

from typing import Final

from manip.arm.kinematics import joint_mask
from manip.arm.sim import AbortCause, FollowingWarning, MotionAborted, Refused
from manip.codecs.error_string import SPECIALS, ErrorMessage

__all__ = [
    "RequestError",
    "abort_error",
    "bad_float",
    "bad_length",
    "bad_value",
    "guard_stop_error",
    "internal_error",
    "not_served",
    "nzi_error",
    "refusal_error",
    "unknown_opcode",
    "warning_error",
]

MOVE: Final = "move"
"""Where asynchronous errors of the move process come from."""
WRIST: Final = "wrist"
"""Where errors of the wrist computer and its link come from."""
DISPATCH: Final = "dispatch"
"""Where errors found before a request reaches its handler come from."""


class RequestError(Exception):
    """A request answered with an error string; ``fatal`` errors close the connection."""

    def __init__(self, error: ErrorMessage, *, fatal: bool = False) -> None:
        super().__init__(error.render())
        self.error = error
        self.fatal = fatal


def _plain(detail: str) -> str:
    """A detail text safe in a message: ASCII, and without the special characters ~ and $."""
    out = "".join(ch if " " <= ch <= "~" and ch not in SPECIALS else "?" for ch in detail)
    return out[:1].upper() + out[1:]


# code -> (severity, message); a message with $ takes the refusal's joint mask.
_REFUSALS: Final[dict[str, tuple[str, str]]] = {
    "NAP": ("E", "No arm power"),
    "AWA": ("E", "Arm motion was aborted; reset before moving"),
    "SQF": ("E", "Segment queue full"),
    "JOR": ("E", "Joint(s) $ out of range"),
    "TOR": ("E", "Transform cannot be reached"),
}
#: TOR for a transform that is reachable but whose every solution breaks a limit (erratum
#: ``transform-refusals``): the joints the nearest configuration breaks go in the mask.
_TOR_LIMITS: Final = "Every solution of the transform puts joint(s) $ out of range"


def refusal_error(where: str, refusal: Refused) -> RequestError:
    """The non-fatal error answering a request the arm refused."""
    if refusal.code in _REFUSALS:
        code = refusal.code
        severity, message = _REFUSALS[refusal.code]
        if refusal.code == "TOR":
            limits = bool(refusal.joints)
            message = _TOR_LIMITS if limits else f"{message} ({_plain(refusal.detail).lower()})"
        args = (joint_mask(refusal.joints),) if "$" in message else ()
        return RequestError(ErrorMessage(where, severity, code, message, args))
    return RequestError(ErrorMessage(where, "C", refusal.code, _plain(refusal.detail)))


def bad_value(where: str, detail: str) -> RequestError:
    """C BVA: an argument outside its allowed range."""
    return RequestError(ErrorMessage(where, "C", "BVA", _plain(detail)))


def unknown_opcode(opcode: int) -> RequestError:
    """Erratum ``unknown-opcode``: exactly ``dispatch: C UOP Unknown opcode ~``."""
    return RequestError(ErrorMessage(DISPATCH, "C", "UOP", "Unknown opcode ~", (opcode,)))


def not_served(opcode: int) -> RequestError:
    """A wrist opcode on a robot without a wrist computer: C UIM, whatever its data, as an unknown
    opcode is refused whatever its data (erratum describe-self-truthful: describe self does not list
    it, and a client probing it learns the same)."""
    return RequestError(
        ErrorMessage(WRIST, "C", "UIM", "No wrist computer: opcode ~ is not served", (opcode,))
    )


def bad_length(expected: int, received: int) -> RequestError:
    """Erratum ``data-length``: C BDL with the expected and received byte counts."""
    return RequestError(
        ErrorMessage(
            DISPATCH, "C", "BDL", "Bad data length, ~ bytes expected, ~ received", (expected, received)
        )
    )


def bad_float(word: int) -> RequestError:
    """Erratum ``float-decode``: C BFL with the index of the data word where the bad float starts."""
    return RequestError(ErrorMessage(DISPATCH, "C", "BFL", "Reserved-operand float at data word ~", (word,)))


def internal_error(opcode: int) -> RequestError:
    """BE BUG: the handler failed; the request was not (fully) carried out."""
    return RequestError(ErrorMessage(DISPATCH, "BE", "BUG", "Internal error serving opcode ~", (opcode,)))


def nzi_error(joints: tuple[int, ...]) -> RequestError:
    """The 1985 guide's own example (E.2): calibration found no zero index; fatal."""
    return RequestError(
        ErrorMessage(
            "During calibration", "F", "NZI", "No zero index found on joint(s) $.", (joint_mask(joints),)
        ),
        fatal=True,
    )


def abort_error(event: MotionAborted) -> ErrorMessage:
    """The asynchronous error (0204) reporting an abort of the move process."""
    match event.cause:
        case AbortCause.COLLISION:
            return ErrorMessage(
                MOVE,
                "E",
                "COL",
                "Collision on joint(s) $; arm stopped, motion aborted",
                (joint_mask(event.joints),),
            )
        case AbortCause.PANIC:
            return ErrorMessage(MOVE, "E", "PAN", "Panic button pressed; arm power off, motion aborted")
        case AbortCause.POWER_LOST:
            return ErrorMessage(MOVE, "E", "NAP", "Arm power lost while moving; motion aborted")
        case AbortCause.GUARD:
            return ErrorMessage(MOVE, "E", "GRD", "A wrist guard stopped the move; motion aborted")


def guard_stop_error(index: int) -> ErrorMessage:
    """The asynchronous error (0204) for a stop-the-move guard trip the client did not ask to hear of
    as a guard-hit response (erratum ``guard-stop``): the abort is never silent."""
    return ErrorMessage(WRIST, "E", "GRD", "Guard ~ tripped; arm stopped, motion aborted", (index,))


def warning_error(event: FollowingWarning) -> ErrorMessage:
    """The asynchronous warning (0205) for joints lagging the commanded angles."""
    return ErrorMessage(
        MOVE, "W", "COL", "Joint(s) $ lagging the commanded angles", (joint_mask(event.joints),)
    )
