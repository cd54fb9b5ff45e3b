"""The Puma side of Cougar on its own: CougarWrist in a ServerSession, against a scripted Cougar.

The fake (tests/support/cougar_fake.py) only speaks Table 1 words; these tests check what the Puma sends,
when, in which order, and what the client gets back.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pytest

from manip.arm.kinematics import READY
from manip.arm.trajectory import PUMA_LIMITS, TICK, Scheme
from manip.codecs.messages import AsyncResponse, ErrorReply, Reply
from manip.reference_server import State
from manip.reference_server.cougar_port import SimPort
from manip.reference_server.cougar_wrist import CougarWrist
from manip.reference_server.session import WRIST_OPERATIONS
from manip.spec import SPEC
from manip.spec.constants import AsyncCondition, CougarCommand, ServerOp
from tests.support.cougar_fake import FakeCougar, WristClient

J2_WALL = -70.0
INTO_WALL = (0.0, -40.0, 90.0, 0.0, 0.0, 0.0)
READY_J = READY


def _setup(**fake: Any) -> tuple[WristClient, FakeCougar, CougarWrist]:
    cougar = FakeCougar(**fake)
    wrist = CougarWrist(SimPort(cougar))
    return WristClient(wrist), cougar, wrist


def _reply(msg: object) -> Reply:
    assert isinstance(msg, Reply), msg
    return msg


def _error(msg: object, opcode: int = ServerOp.NON_FATAL_ERROR) -> ErrorReply:
    assert isinstance(msg, ErrorReply), msg
    assert msg.opcode == opcode, msg
    return msg


# ------------------------------------------------------------------------------ data requests
def test_every_wrist_opcode_is_served_and_described() -> None:
    client, _, wrist = _setup()
    opcodes = {SPEC.request(name).opcode for name in WRIST_OPERATIONS}
    assert wrist.served == opcodes
    assert opcodes <= set(client.session.operations)


def test_read_forces_waits_for_cougar_and_sends_the_angles_first() -> None:
    client, cougar, _ = _setup(wall_at=-100.0)  # ready has joint 2 at -90: 10 degrees in
    assert client.send("read-forces") == []  # the main process waits: no answer yet
    assert client.session.state is State.WRIST_WAIT
    msg = _reply(client.tick()[0])
    assert msg.values["forces"] == pytest.approx((50.0, 0, 0, 0, 0, 0))
    codes = [m.code for m in cougar.log]
    assert codes.index(CougarCommand.SEN) < codes.index(CougarCommand.RFRC)
    state: State = client.session.state  # read again: the tick changed it (mypy keeps the narrowing)
    assert state is State.READY


def test_read_raw_gauges_examine_deposit_and_version() -> None:
    client, cougar, wrist = _setup()
    raw = _reply(client.call("read-raw-gauges")).values["gauges"]
    assert raw == cougar.gauges()
    assert _reply(client.call("deposit-wrist", address=0o1000, value=0o123456)).is_empty
    words = _reply(client.call("examine-wrist", address=0o777, count=3)).values["words"]
    assert words == (0, 0o123456, 0)
    assert _reply(client.call("wrist-version")).values["version"] == 0o105
    (vers,) = cougar.commands(CougarCommand.VERS)
    assert vers.values["version"] == wrist.version


def test_examine_refuses_more_than_a_packet_holds() -> None:
    client, _, _ = _setup()
    err = _error(client.call("examine-wrist", address=0, count=243))
    assert (err.error.severity, err.error.code) == ("C", "BVA")


CONFIG = [
    (
        "set-spring",
        {"k": (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)},
        CougarCommand.NK,
        {"k": (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)},
    ),
    (
        "set-damping",
        {"b": tuple(float(i) for i in range(36))},
        CougarCommand.NB,
        {"b": tuple(float(i) for i in range(36))},
    ),
    ("set-joint-damping", {"bji": (0.5,) * 6}, CougarCommand.NBJI, {"bji": (0.5,) * 6}),
    ("set-frame-vector", {"offset": (0.0, 0.0, 5.5)}, CougarCommand.NFV, {"offset": (0.0, 0.0, 5.5)}),
    (
        "set-weight",
        {"weight": 12.0, "cg": (1.0, 0.0, 3.0)},
        CougarCommand.NEWWC,
        {"weight": 12.0, "cg": (1.0, 0.0, 3.0)},
    ),
    (
        "set-commanded-force",
        {"force": (0.0, 0.0, -8.0, 0.0, 0.0, 0.0)},
        CougarCommand.NFC,
        {"force": (0.0, 0.0, -8.0, 0.0, 0.0, 0.0)},
    ),
    (
        "set-gauge-offsets",
        {"offsets": (1, -2, 3, -4, 5, -6, 7, -8)},
        CougarCommand.WGOV,
        {"offsets": (1, -2, 3, -4, 5, -6, 7, -8)},
    ),
    ("deposit-wrist", {"address": 5, "value": 0xBEEF}, CougarCommand.DPST, {"address": 5, "value": 0xBEEF}),
    ("clear-guard", {"index": 9}, CougarCommand.GUARDC, {"index": 9}),
    (
        "set-guard",
        {"type_index": 0x8FF5, "dvec": (0.0, 0.0, 1.0, 0.0, 0.0, 0.0), "tol": 4.0},
        CougarCommand.GUARDS,
        {"type_index": 0x8005, "dvec": (0.0, 0.0, 1.0, 0.0, 0.0, 0.0), "tol": 4.0},
    ),
]


@pytest.mark.parametrize(("op", "values", "command", "sent"), CONFIG, ids=[c[0] for c in CONFIG])
def test_configuration_is_answered_at_once_and_reaches_cougar(
    op: str, values: dict[str, Any], command: int, sent: dict[str, Any]
) -> None:
    client, cougar, _ = _setup()
    (msg,) = client.send(op, **values)
    assert _reply(msg).is_empty  # §5.1: queued for the wrist process, answered without waiting
    assert cougar.commands(command) == []
    client.tick()
    (cmd,) = cougar.commands(command)
    assert dict(cmd.values) == sent


# -------------------------------------------------------------------------------- waiting
def test_a_silent_cougar_gives_a_non_fatal_timeout_and_later_requests_wait_in_order() -> None:
    client, cougar, wrist = _setup(silent={CougarCommand.RFRC})
    start = client.now
    client.send("read-forces")
    number = client.packet_no
    client.send("joint-angles")  # held: the main process is waiting
    client.send("wrist-version")  # held too, then itself waits for Cougar
    answers: list[Any] = []
    while len([m for m in answers if isinstance(m, Reply | ErrorReply)]) < 3:
        answers += client.tick()
        assert client.now - start < 2.0
    err = _error(answers[0])
    assert err.request_number == number
    assert (err.error.where, err.error.severity, err.error.code) == ("wrist", "E", "WNR")
    assert err.error.args == (CougarCommand.RFRC, 500)
    assert wrist.reply_timeout <= client.now - start < wrist.reply_timeout + 3 * TICK
    assert [m.request_number for m in answers] == [number, number + 1, number + 2]
    assert _reply(answers[2]).values["version"] == cougar.version


def test_a_late_reply_to_a_timed_out_request_is_not_taken_for_the_next_one() -> None:
    client, cougar, wrist = _setup()
    port = wrist.port
    assert isinstance(port, SimPort)
    held: list[int] = []
    real_receive = port.receive

    def slow_receive() -> list[int]:  # hold Cougar's words back until released
        held.extend(real_receive())
        return []

    port.receive = slow_receive  # type: ignore[method-assign]
    _error(client.call("read-raw-gauges"))
    port.receive = real_receive  # type: ignore[method-assign]
    cougar.offsets = (1, 1, 1, 1, 1, 1, 1, 1)
    fresh = cougar.gauges()
    port._inbox[:0] = held  # the late reply arrives first
    assert _reply(client.call("read-raw-gauges")).values["gauges"] == fresh
    assert wrist.stats.stale_replies == 1


def test_out_of_sync_fails_the_waiting_request_and_warns() -> None:
    client, _cougar, _ = _setup(out_of_sync_on=CougarCommand.RRAW)
    err = _error(client.call("read-raw-gauges"))
    assert err.error.code == "OOS"
    (warning,) = client.errors(ServerOp.ASYNCHRONOUS_WARNING)
    assert warning.error.code == "OOS"


def test_link_down_fails_at_once_and_is_reported_once() -> None:
    client, _, wrist = _setup()
    wrist.port.close()
    client.run(0.1)
    (notice,) = client.errors(ServerOp.ASYNCHRONOUS_ERROR)
    assert notice.error.code == "WLK"
    (msg,) = client.send("read-forces")
    assert _error(msg).error.code == "WLK"
    client.run(0.1)
    assert len(client.errors(ServerOp.ASYNCHRONOUS_ERROR)) == 1


def test_closing_while_waiting_cancels_the_wait() -> None:
    client, _, _ = _setup(silent={CougarCommand.RFRC})
    client.send("read-forces")
    client.session.on_close(client.now + 0.01)
    assert client.session.state is State.CLOSED


# --------------------------------------------------------------------------------- guards
def _guarded(stop: bool, notify: bool) -> tuple[WristClient, FakeCougar, int]:
    client, cougar, _ = _setup(wall_at=J2_WALL)
    if notify:
        client.call("request-notifications", mask=0b11)
    type_index = 3 | (0x8000 if stop else 0)
    client.call("set-guard", type_index=type_index, dvec=(1.0, 0.0, 0.0, 0.0, 0.0, 0.0), tol=10.0)
    segment = _reply(client.call("set-joint-angles", joints=INTO_WALL)).values["segment"]
    assert isinstance(segment, int)
    client.run(4.0)
    return client, cougar, segment


def _guard_hits(client: WristClient) -> list[AsyncResponse]:
    return [a for a in client.asyncs() if a.condition == AsyncCondition.GUARD_HIT]


def test_a_stop_guard_trips_once_and_stops_the_move() -> None:
    client, _cougar, segment = _guarded(stop=True, notify=True)
    (hit,) = _guard_hits(client)
    assert (hit.word2, hit.word3) == (1, 3)
    arm = client.session.arm
    assert not arm.moving and arm.aborted
    assert J2_WALL + 2.0 < arm.actual[1] < J2_WALL + 6.0  # stopped just past the trip point
    completed = [a.word3 for a in client.asyncs() if a.condition == AsyncCondition.SEGMENT_COMPLETED]
    assert segment not in completed  # dropped
    assert client.errors(ServerOp.ASYNCHRONOUS_ERROR) == []  # the guard hit is the report
    assert _error(client.call("set-joint-angles", joints=INTO_WALL)).error.code == "AWA"
    client.call("reset-abort")
    assert isinstance(_reply(client.call("set-joint-angles", joints=INTO_WALL)).values["segment"], int)


def test_a_continue_guard_reports_and_the_move_goes_on() -> None:
    client, _, segment = _guarded(stop=False, notify=True)
    (hit,) = _guard_hits(client)
    assert (hit.word2, hit.word3) == (2, 3)
    arm = client.session.arm
    assert not arm.aborted and arm.actual == pytest.approx(INTO_WALL)
    completed = [a.word3 for a in client.asyncs() if a.condition == AsyncCondition.SEGMENT_COMPLETED]
    assert completed == [segment]


def test_guard_hits_are_sent_only_when_asked_for() -> None:
    client, _, _ = _guarded(stop=False, notify=False)
    assert client.asyncs() == [] and client.errors(ServerOp.ASYNCHRONOUS_ERROR) == []
    client, _, _ = _guarded(stop=True, notify=False)
    assert client.asyncs() == []
    (err,) = client.errors(ServerOp.ASYNCHRONOUS_ERROR)  # a stop is never silent
    assert (err.error.code, err.error.args) == ("GRD", (3,))
    assert client.session.arm.aborted


def test_the_segments_a_stop_guard_drops_are_named_in_a_warning() -> None:
    for notify in (True, False):
        client, _, _ = _setup(wall_at=J2_WALL)
        if notify:
            client.call("request-notifications", mask=0b11)
        client.call("set-guard", type_index=0x8000 | 3, dvec=(1.0, 0.0, 0.0, 0.0, 0.0, 0.0), tol=10.0)
        numbers = [
            _reply(client.call("set-joint-angles", joints=joints)).values["segment"]
            for joints in (INTO_WALL, READY_J, INTO_WALL)
        ]
        client.run(4.0)
        completed = [a.word3 for a in client.asyncs() if a.condition == AsyncCondition.SEGMENT_COMPLETED]
        assert completed == []  # none of them will ever complete...
        (warning,) = client.errors(ServerOp.ASYNCHRONOUS_WARNING)  # ...and the client is told so, once
        assert (warning.error.where, warning.error.severity, warning.error.code) == ("wrist", "W", "AWA")
        assert warning.error.args == (3, 3, numbers[0], numbers[2])
        assert warning.error.problems == ()
        # Besides the guard hit (asked for) or the guard-stop error (not asked for): no other report.
        assert len(_guard_hits(client)) == (1 if notify else 0)
        assert len(client.errors(ServerOp.ASYNCHRONOUS_ERROR)) == (0 if notify else 1)


def test_a_stop_guard_that_drops_nothing_warns_of_nothing() -> None:
    client, _, _ = _setup(wall_at=J2_WALL)
    client.call("request-notifications", mask=0b01)
    client.call("compliant-move", joints=INTO_WALL, scheme=0)
    client.run(4.0)  # the arm now rests against the wall, idle
    client.call("set-guard", type_index=0x8000 | 4, dvec=(1.0, 0.0, 0.0, 0.0, 0.0, 0.0), tol=1e-3)
    client.run(0.5)
    assert [(h.word2, h.word3) for h in _guard_hits(client)] == [(1, 4)]
    assert client.errors(ServerOp.ASYNCHRONOUS_WARNING) == []
    assert not client.session.arm.aborted  # an idle arm has nothing to stop


# ----------------------------------------------------------------------------- compliance
def _compliant(scheme: int) -> tuple[WristClient, CougarWrist, list[float], list[float]]:
    client, _, wrist = _setup(wall_at=J2_WALL)
    client.call("compliant-move", joints=INTO_WALL, scheme=scheme)
    actual: list[float] = []
    nominal: list[float] = []
    arm = client.session.arm
    while (arm.moving and arm.current_scheme is not None) or not actual:
        client.tick()
        if arm.current_scheme is not None:
            actual.append(arm.actual[1])
            nominal.append(wrist.meter[-1].nominal[1])
    return client, wrist, actual, nominal


def test_under_compliance_the_arm_yields_to_the_contact() -> None:
    _, wrist, actual, nominal = _compliant(0)
    assert max(nominal) > J2_WALL + 25.0  # the nominal path goes deep into the wall
    assert max(actual) < J2_WALL + 4.0  # the arm gave way
    assert wrist.stats.npr >= len(actual) - 1  # NPR every servo cycle
    assert all(e.scheme is Scheme.COMPLIANT_MOTION for e in wrist.meter)


def test_a_servo_that_wakes_late_sends_an_npr_for_every_cycle_it_catches_up() -> None:
    """A loaded host wakes the servo late; it runs the cycles it missed at once, and the wrist still
    hears one New Position and Rate for each of them (Part II: NPR every cycle of a compliant segment)."""
    client, _, wrist = _setup(wall_at=J2_WALL)
    client.call("compliant-move", joints=INTO_WALL, scheme=0)
    client.run(0.2)
    assert client.session.arm.current_scheme is not None
    before, last = wrist.stats.npr, wrist.meter[-1].time
    client.now += 5 * TICK  # the next tick comes with five more servo cycles overdue
    client.tick()
    ran = sum(1 for entry in wrist.meter if entry.time > last + 1e-9)  # compliant cycles run by that tick
    assert ran == 6
    assert wrist.stats.npr - before == ran


def test_the_ntd_used_is_from_an_earlier_tick() -> None:
    client, _, wrist = _setup(wall_at=J2_WALL)
    client.call("compliant-move", joints=INTO_WALL, scheme=0)
    client.run(1.0)
    entries = list(wrist.meter)
    # Cougar answers the NPR of cycle k (with the angles sensed then) during tick k; cycle k+1 uses it.
    checked = 0
    for before, after in itertools.pairwise(entries):
        if after.ntd[1] != 0.0:
            checked += 1
            expected = -4.0 * 5.0 * max(0.0, before.sensed[1] - J2_WALL)
            assert after.ntd[1] == pytest.approx(expected, rel=1e-5, abs=1e-4)
    assert checked > 10


def test_a_compliant_segment_ends_at_the_wall_and_the_next_one_starts_there() -> None:
    client, _, wrist = _setup(wall_at=J2_WALL)
    client.call("request-notifications", mask=0b10)
    pressed = _reply(client.call("compliant-move", joints=INTO_WALL, scheme=0)).values["segment"]
    back = _reply(client.call("set-joint-angles", joints=READY_J)).values["segment"]
    assert isinstance(pressed, int)
    arm = client.session.arm
    trace = [arm.commanded]
    ends: dict[int, int] = {}
    for _ in range(round(8.0 / TICK)):
        for msg in client.tick():
            if isinstance(msg, AsyncResponse) and msg.condition == AsyncCondition.SEGMENT_COMPLETED:
                ends[msg.word3] = len(trace)
        trace.append(arm.commanded)
    k = ends[pressed]
    assert J2_WALL < trace[k][1] < J2_WALL + 4.0  # held against the wall, not on the nominal goal
    assert wrist.meter[-1].nominal[1] > J2_WALL + 25.0
    steps = np.abs(np.diff(np.asarray(trace[k - 1 :]), axis=0))
    assert np.all(steps <= PUMA_LIMITS.speed * TICK + 1e-9)  # no jump from there on
    assert back in ends and trace[-1] == pytest.approx(READY_J, abs=1e-9)


def test_the_debugging_scheme_runs_compliance_open_loop() -> None:
    _, wrist, actual, nominal = _compliant(1)
    assert actual == pytest.approx(nominal)
    assert any(e.ntd[1] < 0.0 for e in wrist.meter)  # Cougar was consulted all along
    assert all(e.scheme is Scheme.COMPLIANT_DEBUG for e in wrist.meter)


def test_compliant_move_checks_its_scheme_and_the_arm() -> None:
    client, _, _ = _setup()
    assert _error(client.call("compliant-move", joints=INTO_WALL, scheme=2)).error.code == "BVA"
    bad = (0.0, -40.0, 300.0, 0.0, 0.0, 0.0)
    assert _error(client.call("compliant-move", joints=bad, scheme=0)).error.code == "JOR"


# ---------------------------------------------------------------------------- calibration
def test_calibrate_wrist_recovers_the_offsets_and_returns() -> None:
    client, cougar, _ = _setup()
    start = client.session.arm.actual
    msg = _reply(client.call("calibrate-wrist", limit=60.0))
    offsets = msg.values["offsets"]
    assert isinstance(offsets, tuple)
    assert all(abs(a - b) <= 1 for a, b in zip(offsets, cougar.offsets, strict=True)), offsets
    (wgov,) = cougar.commands(CougarCommand.WGOV)
    assert wgov.values["offsets"] == offsets
    client.run(8.0)
    assert client.session.arm.actual == pytest.approx(start)
    assert len(cougar.commands(CougarCommand.RRAW)) == 16


def test_calibrate_wrist_needs_arm_power() -> None:
    cougar = FakeCougar()
    client = WristClient(CougarWrist(SimPort(cougar)), powered=False)
    assert _error(client.call("calibrate-wrist")).error.code == "NAP"
