"""The asynchronous scenarios' judges read a fatal error's string after its request number, however
short its where field."""

from __future__ import annotations

from manip.codecs.error_string import ErrorMessage
from manip.codecs.messages import encode_error
from manip.conformance.diff.pairing import SideEvent
from manip.conformance.diff.scenarios.asyncs import _check_nzi
from manip.spec.constants import ServerOp


def test_an_nzi_with_an_empty_where_and_a_wrong_mask_is_seen() -> None:
    error = ErrorMessage("", "F", "NZI", "no zero index: joints ~", (4,))
    data = encode_error(ServerOp.FATAL_ERROR, 3, error)
    assert data[2:].startswith(b": ")
    sightings = _check_nzi(0)({0: [SideEvent("packet", ServerOp.FATAL_ERROR, data)]})
    assert [s.violation.clause for s in sightings] == ["calibrate.nzi-mask"]
