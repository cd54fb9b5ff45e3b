"""The request scenarios' judges read a non-fatal error's string after its request number, however short
its where field: a correct error whose where is empty is read as the error it is."""

from __future__ import annotations

from manip.codecs.error_string import ErrorMessage
from manip.codecs.messages import encode_error
from manip.conformance.diff.pairing import SideEvent
from manip.conformance.diff.scenarios.kit import Events, opcode_of
from manip.conformance.diff.scenarios.requests import _check_bad_joints, _check_reset
from manip.spec.constants import RequestName, ServerOp


def _refused(name: RequestName, severity: str, code: str) -> Events:
    """Input 0: request ``name`` answered with a non-fatal error ``: severity code ...`` (where empty)."""
    error = ErrorMessage("", severity, code, "refused")
    data = encode_error(ServerOp.NON_FATAL_ERROR, 7, error)
    assert data[2:].startswith(b": ")
    return {0: [SideEvent("packet", ServerOp.NON_FATAL_ERROR, data, request=opcode_of(name))]}


def test_a_command_error_with_an_empty_where_refuses_a_bad_joint() -> None:
    assert _check_bad_joints({0: 7})(_refused("free-joint", "C", "BJN")) == []


def test_an_awa_with_an_empty_where_is_seen_after_enable_power() -> None:
    sightings = _check_reset(0)(_refused("set-joint-angles", "E", "AWA"))
    assert [s.violation.clause for s in sightings] == ["motion.reset"]
