"""The protocol model of the stateful case, alone: what it allows for each request in each state, how
replies and asynchronous packets move it, and the errata it applies (abort-before-power,
abort-on-power-loss, free-joint-replies)."""

from __future__ import annotations

import struct

import pytest

from manip.codecs.error_string import ErrorMessage
from manip.codecs.messages import encode_request
from manip.conformance.judge.model import AnswerSummary, Expectation, ProtocolModel
from manip.spec import SPEC

READY = [0.0, -90.0, 90.0, 0.0, 0.0, 0.0]
DONE = AnswerSummary(True, empty=True)


def op(name: str) -> int:
    return SPEC.request(name).opcode


def refusal(code: str, severity: str = "E") -> AnswerSummary:
    return AnswerSummary(False, error=ErrorMessage("test", severity, code, "refused"))


class Session:
    """Drives a model like the machine does: number requests, judge, observe."""

    def __init__(self, **state: object) -> None:
        self.model = ProtocolModel(**state)  # type: ignore[arg-type]
        self.number = 10
        self.model.sent(self.number, initial=True)

    def expect(self, name: str, **values: object) -> Expectation:
        return self.model.expect(op(name), encode_request(name, **values))

    def do(self, name: str, reply: AnswerSummary, **values: object) -> Expectation:
        self.number += 1
        data = encode_request(name, **values)
        self.model.sent(self.number)
        expectation = self.model.expect(op(name), data)
        finding = self.model.judge(expectation, reply)
        assert finding is None, finding
        self.model.observe(self.number, op(name), data, reply)
        return expectation


def test_power_unknown_allows_both_and_the_reply_settles_it() -> None:
    s = Session()
    e = s.expect("set-joint-angles", joints=READY)
    assert e.normal and {"NAP", "AWA"} <= e.codes
    s.do("set-joint-angles", refusal("NAP"), joints=READY)
    assert s.model.powered is False
    assert s.model.aborted is False  # NAP means no abort was pending (erratum abort-before-power)
    assert s.expect("ready").codes == frozenset({"NAP"})
    assert not s.expect("ready").normal


def test_nap_when_power_is_off_and_a_segment_when_on() -> None:
    s = Session(powered=False, aborted=False)
    e = s.expect("ready")
    assert not e.normal and e.codes == frozenset({"NAP"}) and e.clause == "motion.no-power"
    assert s.model.judge(e, AnswerSummary(True, segment=1)) is not None
    s.do("enable-power", DONE)
    e = s.expect("ready")
    assert e.normal and not e.codes
    assert s.model.judge(e, refusal("NAP")) is not None
    s.do("ready", AnswerSummary(True, segment=1))
    assert s.model.outstanding == [1]


def test_jor_only_for_joints_past_a_limit() -> None:
    s = Session(powered=True, aborted=False)
    far = [170.0, -90.0, 90.0, 0.0, 0.0, 0.0]
    e = s.expect("set-joint-angles", joints=far)
    assert not e.normal and e.codes == frozenset({"JOR"}) and e.clause == "motion.checked-before-queue"
    assert s.expect("set-joint-angles", joints=READY).normal
    unpowered = Session(powered=False, aborted=False)
    assert unpowered.expect("set-joint-angles", joints=far).codes == frozenset({"NAP", "JOR"})
    assert s.model.judge(e, refusal("TOR")) is not None  # joint angles are JOR, never TOR
    increment = s.expect("incremental-move", delta=[1e4, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert increment.normal and increment.codes == frozenset({"TOR"})


def test_awa_comes_before_nap_and_is_reset_by_reset_abort_or_power() -> None:
    s = Session(powered=False, aborted=True)
    e = s.expect("ready")
    assert not e.normal and e.codes == frozenset({"AWA"}) and e.clause == "motion.abort"
    assert s.model.judge(e, refusal("NAP")) is not None
    s.do("reset-abort", DONE)
    assert s.expect("ready").codes == frozenset({"NAP"})
    s2 = Session(powered=False, aborted=True)
    s2.do("enable-power", DONE)
    assert s2.expect("ready").normal


def test_kill_power_while_moving_then_async_error_is_an_abort() -> None:
    s = Session(powered=True, aborted=False)
    s.do("set-joint-angles", AnswerSummary(True, segment=5), joints=READY)
    s.do("kill-power", DONE)
    assert s.model.aborted is None  # the move process may or may not have noticed yet
    assert s.expect("ready").codes >= {"AWA", "NAP"}
    error = ErrorMessage("move", "E", "NAP", "Arm power lost while moving; motion aborted")
    assert s.model.on_async_error(s.number, error) is None
    assert s.model.aborted is True and s.model.outstanding == []
    assert s.expect("ready").codes == frozenset({"AWA"})


def test_kill_power_while_idle_is_no_abort() -> None:
    s = Session(powered=True, aborted=False)
    s.do("kill-power", DONE)
    assert s.model.aborted is False
    assert s.expect("ready").codes == frozenset({"NAP"})


def test_segment_completed_only_when_asked_for_by_the_mask_after_that_request() -> None:
    s = Session(powered=True, aborted=False)
    s.do("ready", AnswerSummary(True, segment=1))
    finding = s.model.on_async_response(s.number, 2, 0, 1)
    assert finding is not None and finding.clause == "async.only-when-requested"
    s.do("request-notifications", DONE, mask=2)
    s.do("ready", AnswerSummary(True, segment=2))
    assert s.model.on_async_response(s.number, 2, 0, 2) is None
    assert s.model.outstanding == []  # segment 1 finished before 2, silently
    again = s.model.on_async_response(s.number, 2, 0, 2)
    assert again is not None and again.clause == "async.layout"


def test_async_response_must_name_a_request_not_older_than_the_last_answered() -> None:
    s = Session(powered=True, aborted=False)
    s.do("request-notifications", DONE, mask=3)
    s.do("ready", AnswerSummary(True, segment=1))
    stale = s.model.on_async_response(s.number - 1, 2, 0, 1)
    assert stale is not None and stale.clause == "async.layout"
    unknown = s.model.on_async_response(999, 2, 0, 1)
    assert unknown is not None
    bad_code = s.model.on_async_response(s.number, 7, 0, 0)
    assert bad_code is not None and bad_code.clause == "async.codes"


def test_segment_numbers_that_do_not_increase_are_a_should_finding() -> None:
    s = Session(powered=True, aborted=False)
    s.do("ready", AnswerSummary(True, segment=1))
    s.do("ready", AnswerSummary(True, segment=1))
    s.do("ready", AnswerSummary(True, segment=2))
    assert [f.clause for f in s.model.segment_violations] == ["segment.number-increases"]
    assert SPEC.clauses["segment.number-increases"].level == "SHOULD"


def test_free_joint_discards_the_next_packet_whatever_it_is() -> None:
    s = Session(powered=True, aborted=False)
    s.do("free-joint", DONE, joint=3)
    assert s.model.free_wait
    e = s.expect("here")
    assert e.discard and e.clause == "free-joint.replies"
    assert s.model.judge(e, AnswerSummary(True)) is not None  # a Here reply: the packet was executed
    s.do("kill-power", DONE)
    assert s.model.powered is True  # discarded, so not executed
    assert not s.model.free_wait


def test_free_joint_number_out_of_range_is_a_command_error() -> None:
    s = Session(powered=True, aborted=False)
    for joint in (0, 7, 255):
        e = s.expect("free-joint", joint=joint)
        assert e.command and not e.normal and e.clause == "free-joint.data"
    assert s.model.judge(s.expect("free-joint", joint=0), refusal("BVA", "C")) is None
    assert s.model.judge(s.expect("free-joint", joint=0), refusal("BVA", "E")) is not None


@pytest.mark.parametrize("factor", [0.0, -1.0, 1.0000001192092896, 2.0])
def test_speed_out_of_range_is_a_command_error(factor: float) -> None:
    e = Session().expect("set-speed", factor=factor)
    assert e.command and not e.normal and e.clause == "speed.range"


def test_speed_in_range_is_done() -> None:
    e = Session().expect("set-speed", factor=2.0**-120)
    assert e.normal and not e.command


def test_malformed_requests_are_command_errors() -> None:
    m = ProtocolModel()
    unknown = m.expect(0o222, b"")
    assert unknown.command and not unknown.normal and unknown.clause == "request.unknown-opcode"
    short = m.expect(op("set-speed"), b"\x00\x00")
    assert short.clause == "request.data-length" and not short.normal
    reserved = m.expect(op("set-speed"), struct.pack("<I", 0x8000))
    assert reserved.clause == "request.reserved-float" and not reserved.normal


def test_a_transform_that_is_no_rotation_is_a_command_error() -> None:
    s = Session(powered=True, aborted=False)
    e = s.expect("move", transform=[2.0] * 12)
    assert e.command and not e.normal
    identity = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 500.0]
    e = s.expect("move", transform=identity)
    assert e.normal and e.codes == frozenset({"TOR"})  # the model cannot tell reachability; never JOR
    assert s.model.judge(e, refusal("JOR")) is not None  # erratum transform-refusals
    s.model.reachable.add(tuple(identity))
    e = s.expect("move", transform=identity)
    assert e.normal and not e.codes  # the server's own transform of in-range angles


def test_fatal_and_bug_errors_are_never_allowed() -> None:
    m = ProtocolModel()
    e = m.expect(op("here"), b"")
    assert m.judge(e, refusal("BUG", "BE")) is not None
    assert m.judge(e, refusal("NZI", "F")) is not None
    assert m.judge(e, AnswerSummary(True)) is None


def test_extensions_the_server_does_not_list_may_be_refused_as_unserved() -> None:
    listed = ProtocolModel(served=frozenset({op("reset-abort")}))
    assert not listed.expect(op("reset-abort"), b"").command
    assert listed.expect(op("request-notifications"), encode_request("request-notifications", mask=2)).command
    unknown = ProtocolModel()
    assert unknown.expect(op("reset-abort"), b"").command
    assert not unknown.expect(op("enable-power"), b"").command  # the 1985 guide's opcodes are never optional


def test_an_unlisted_extension_may_be_refused_as_unserved_whatever_the_arm_s_state() -> None:
    m = ProtocolModel(powered=False, aborted=True)
    move = encode_request("compliant-move", joints=(0.0,) * 6, scheme=0)
    e = m.expect(op("compliant-move"), move)
    assert not e.normal and e.codes == {"AWA"}
    assert m.judge(e, refusal("UIM", "C")) is None  # not served at all: not refused for the abort
    assert m.judge(e, AnswerSummary(True, segment=1)) is not None
    listed = ProtocolModel(powered=False, aborted=True, served=frozenset({op("compliant-move")}))
    assert listed.judge(listed.expect(op("compliant-move"), move), refusal("UIM", "C")) is not None


def test_configuration_bits_besides_bit_0_may_be_done_or_refused() -> None:
    # the 1985 guide: "one byte long, with the low bit a 1 for lefty ... The response is a 'done'"
    s = Session()
    e = s.expect("set-configuration", configuration=3)
    assert e.normal and e.command and e.clause == "set-configuration.data"
    assert s.model.judge(e, DONE) is None
    assert s.model.judge(e, refusal("BVA", "C")) is None
    assert s.model.judge(e, refusal("BVA", "E")) is not None


def test_while_segments_run_any_error_code_may_refuse_motion_or_free_joint() -> None:
    # E.2: "others may be used by specific manipulators"; the guide names no code for either condition
    s = Session(powered=True, aborted=False)
    s.do("set-joint-angles", AnswerSummary(True, segment=1), joints=READY)
    for name, values in (("free-joint", {"joint": 2}), ("set-joint-angles", {"joints": READY})):
        e = s.expect(name, **values)
        assert e.normal and e.any_code and "any code" in e.describe()
        for code in ("SQF", "JNF", "BSY"):
            assert s.model.judge(e, refusal(code)) is None
        assert s.model.judge(e, refusal("BUG", "BE")) is not None
    idle = Session(powered=True, aborted=False)
    e = idle.expect("free-joint", joint=2)
    assert not e.any_code and idle.model.judge(e, refusal("JNF")) is not None


def test_an_async_response_in_the_guides_layout_has_no_number_to_judge() -> None:
    s = Session(powered=True, aborted=False)
    s.do("request-notifications", DONE, mask=2)
    s.do("set-joint-angles", AnswerSummary(True, segment=1), joints=READY)
    assert s.model.on_async_response(None, 2, 0, 1) is None
    assert s.model.outstanding == []
    s.do("request-notifications", DONE, mask=0)
    finding = s.model.on_async_response(None, 2, 0, 2)
    assert finding is not None and finding.clause == "async.only-when-requested"
