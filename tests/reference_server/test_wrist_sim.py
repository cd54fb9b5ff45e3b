"""The Puma side with the Cougar simulator: every wrist opcode end to end, guards, compliance against a
simulated surface, calibrate-wrist, and manip-cougar served over TCP to a manip-server."""

from __future__ import annotations

import asyncio
from typing import Any

import numpy as np
import pytest

from manip.arm import Transform
from manip.arm.kinematics import PUMA600, forward
from manip.arm.trajectory import PUMA_LIMITS, TICK
from manip.codecs.messages import AsyncResponse, Reply
from manip.cougar import CougarConfig, CougarSim, GaugeModel, Surface
from manip.cougar.memory import GUARD_WORDS, region
from manip.reference_server.cougar_port import SimPort
from manip.reference_server.cougar_wrist import CougarWrist
from manip.spec.constants import AsyncCondition
from tests.support.cougar_fake import WristClient
from tests.support.servers import MANIP_COUGAR, StartServer

START = PUMA600.ready
GOAL = (0.0, -40.0, 90.0, 0.0, 0.0, 0.0)
TOOL = Transform.trans(0.0, 0.0, 150.0)


def _tool(q: tuple[float, ...]) -> np.ndarray:
    return (forward(q, PUMA600.geometry) @ TOOL).p


def _surface() -> Surface:
    """A plane half way along the move from START to GOAL, facing START: the move goes deep into it."""
    mid = tuple((a + b) / 2 for a, b in zip(START, GOAL, strict=True))
    n = _tool(START) - _tool(mid)
    return Surface(tuple(_tool(mid)), tuple(n / np.linalg.norm(n)), 10.0)


def _setup(config: CougarConfig | None = None, **kw: Any) -> tuple[WristClient, CougarSim]:
    sim = CougarSim(config, seed=1, **kw)
    return WristClient(CougarWrist(SimPort(sim))), sim


def _reply(msg: object) -> Reply:
    assert isinstance(msg, Reply), msg
    return msg


def test_configuration_opcodes_land_in_cougar_memory() -> None:
    client, sim = _setup()
    mem = sim.memory
    cases: list[tuple[str, dict[str, Any], str, tuple[float, ...]]] = [
        ("set-spring", {"k": (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)}, "k", (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)),
        ("set-damping", {"b": tuple(float(i) for i in range(36))}, "b", tuple(float(i) for i in range(36))),
        ("set-joint-damping", {"bji": (0.25,) * 6}, "bji", (0.25,) * 6),
        ("set-frame-vector", {"offset": (0.0, 0.0, 50.0)}, "fv", (0.0, 0.0, 50.0)),
        ("set-weight", {"weight": 8.0, "cg": (0.0, 0.0, 20.0)}, "object", (8.0, 0.0, 0.0, 20.0)),
        (
            "set-commanded-force",
            {"force": (0.0, 0.0, -5.0, 0.0, 0.0, 0.0)},
            "fc",
            (0.0, 0.0, -5.0, 0.0, 0.0, 0.0),
        ),
    ]
    for op, values, name, expected in cases:
        _reply(client.call(op, **values))
        client.tick()
        assert tuple(mem.get(name)) == pytest.approx(expected), op
    _reply(client.call("set-gauge-offsets", offsets=(1, 2, 3, 4, -5, -6, -7, -8)))
    client.tick()
    assert tuple(mem.get_int16s("gauge_offsets")) == (1, 2, 3, 4, -5, -6, -7, -8)


def test_wrist_settings_take_effect_at_once_while_segments_are_queued() -> None:
    """Erratum wrist-config-immediate: a setting sent behind queued motion reaches Cougar on the next
    servo tick, while the segment queued before it still runs and another waits behind it -- not when
    those segments end, as the 1985 guide's segment-synchronised wrist requests would."""
    client, sim = _setup()
    _reply(client.call("set-joint-angles", joints=GOAL))
    _reply(client.call("set-joint-angles", joints=START))
    _reply(client.call("set-spring", k=(7.0,) * 6))
    client.tick()
    arm = client.session.arm
    assert tuple(sim.memory.get("k")) == pytest.approx((7.0,) * 6)
    assert arm.moving and arm.queued >= 1  # the move before it runs, the one after it waits


def test_data_opcodes_read_cougar() -> None:
    client, sim = _setup()
    client.run(0.5)  # let the filter settle on the hand's weight
    forces = _reply(client.call("read-forces")).values["forces"]
    assert isinstance(forces, tuple) and len(forces) == 6
    assert max(abs(f) for f in forces) < 1.0  # free space, gravity corrected
    gauges = _reply(client.call("read-raw-gauges")).values["gauges"]
    assert isinstance(gauges, tuple) and all(-2048 <= g <= 2047 for g in gauges)
    assert _reply(client.call("wrist-version")).values["version"] == sim.config.version
    address = region("flags").address
    _reply(client.call("deposit-wrist", address=address, value=1))
    assert _reply(client.call("examine-wrist", address=address, count=1)).values["words"] == (1,)
    assert sim.memory.word("flags") == 1


def test_a_stop_guard_trips_on_the_surface() -> None:
    surface = _surface()
    client, sim = _setup(environment=surface)
    client.call("request-notifications", mask=1)
    mid = tuple((a + b) / 2 for a, b in zip(START, GOAL, strict=True))
    n_hand = forward(mid, PUMA600.geometry).matrix[:3, :3].T @ np.asarray(surface.normal)
    # Cougar's force is the one the robot applies: into the surface, -n.
    dvec = (*(float(x) for x in -n_hand), 0.0, 0.0, 0.0)
    client.call("set-guard", type_index=0x8000 | 6, dvec=dvec, tol=50.0)
    client.call("set-joint-angles", joints=GOAL)
    client.run(5.0)
    hits = [
        a for a in client.asyncs() if isinstance(a, AsyncResponse) and a.condition == AsyncCondition.GUARD_HIT
    ]
    assert [(h.word2, h.word3) for h in hits] == [(1, 6)]
    arm = client.session.arm
    assert arm.aborted and not arm.moving
    # Stopped soon after the trip (the nominal move goes ~400 mm in): the filter's delay and one tick.
    assert 0.0 < surface.penetration(sim.tool_pose()) < 100.0


def test_under_compliance_the_arm_yields_to_the_surface() -> None:
    surface = _surface()
    depths: dict[int, float] = {}
    for scheme in (0, 1):
        client, sim = _setup(environment=surface)
        client.call("set-joint-damping", bji=(0.1,) * 6)
        client.call("compliant-move", joints=GOAL, scheme=scheme)
        arm = client.session.arm
        deepest = 0.0
        for _ in range(round(6.0 / 0.016)):
            client.tick()
            if arm.current_scheme is not None:
                deepest = max(deepest, surface.penetration(sim.tool_pose()))
        depths[scheme] = deepest
    assert depths[1] > 300.0  # open loop: the nominal path, deep into the surface
    assert depths[0] < 0.2 * depths[1]  # closed loop: the arm gives way


def test_a_compliant_segment_ends_where_the_surface_let_it_go_and_the_next_starts_there() -> None:
    surface = _surface()
    client, sim = _setup(environment=surface)
    client.call("set-joint-damping", bji=(0.1,) * 6)
    client.call("request-notifications", mask=0b10)
    pressed = _reply(client.call("compliant-move", joints=GOAL, scheme=0)).values["segment"]
    back = _reply(client.call("set-joint-angles", joints=START)).values["segment"]
    assert isinstance(pressed, int)
    arm = client.session.arm
    trace = [arm.commanded]
    ends: dict[int, tuple[int, float]] = {}  # segment -> (cycle, penetration) when it completed
    for _ in range(round(10.0 / TICK)):
        for msg in client.tick():
            if isinstance(msg, AsyncResponse) and msg.condition == AsyncCondition.SEGMENT_COMPLETED:
                ends[msg.word3] = (len(trace), surface.penetration(sim.tool_pose()))
        trace.append(arm.commanded)
    assert set(ends) == {pressed, back} and not arm.moving
    k, depth = ends[pressed]
    end = np.asarray(trace[k])
    # Short of the nominal goal, which is deep inside the surface: the arm is not (with this damping
    # the simulated compliance law throws it back out of the contact, and there it stays).
    assert np.max(np.abs(end - np.asarray(GOAL))) > 10.0
    assert depth < 20.0 < surface.penetration(forward(GOAL, PUMA600.geometry) @ TOOL)
    # The next segment starts from there: from the last compliant cycle on no cycle moves a joint's
    # command by more than one tick of nominal motion; it ends on its own goal.
    steps = np.abs(np.diff(np.asarray(trace[k - 1 :]), axis=0))
    assert np.all(steps <= PUMA_LIMITS.speed * TICK + 1e-9)
    assert trace[-1] == pytest.approx(START, abs=1e-9)


def test_calibrate_wrist_recovers_the_gauge_offsets() -> None:
    true = (40, -25, 13, 0, -60, 7, 90, -3)
    client, sim = _setup(CougarConfig(gauges=GaugeModel(offsets=true)))
    offsets = _reply(client.call("calibrate-wrist", limit=60.0)).values["offsets"]
    assert isinstance(offsets, tuple)
    # ADC8's integer filter truncates: a steady reading sits 0..3 counts below the input, so the offsets
    # found are at most 4 counts low (never high).
    assert all(-4 <= a - b <= 0 for a, b in zip(offsets, true, strict=True)), offsets
    client.tick()
    assert tuple(sim.memory.get_int16s("gauge_offsets")) == offsets


# ------------------------------------------------------------------------- manip-cougar over TCP
def test_manip_cougar_serves_a_manip_server(manip_server: StartServer) -> None:
    # Processes on purpose: the two commands, manip-server --cougar linked to manip-cougar, are under test.
    cougar = manip_server("--seed", "3", command=MANIP_COUGAR)
    assert cougar.line.startswith("manip-cougar: listening on")
    server = manip_server("--powered", "--cougar", cougar.url, "--log-level", "WARNING")
    assert server.line.startswith("manip-server: listening on")
    asyncio.run(_use_server(server.url))


async def _use_server(address: str) -> None:
    from manip.reference_client import aconnect

    async with asyncio.timeout(20), aconnect(address) as puma:
        version = await puma.wrist_version()
        assert version == 1
        forces = await puma.read_forces()
        assert len(forces) == 6


@pytest.mark.parametrize(("type_index", "first_word"), [(0x0103, 0x8003), (0x80F3, 0x8003), (0x00F3, 0x0003)])
def test_set_guard_sends_the_stop_bit_for_any_high_byte_bit(type_index: int, first_word: int) -> None:
    """Erratum guard-type-bit: the Puma reads a client's type word as Cougar does (any high-byte bit:
    stop) and sends Cougar bit 15 alone, bits 4-14 cleared."""
    client, sim = _setup()
    _reply(client.call("set-guard", type_index=type_index, dvec=(0.0,) * 6, tol=1.0e30))
    client.tick()
    client.tick()
    assert sim.memory.read_words(region("guards").address + 2 * GUARD_WORDS * 3, 1)[0] == first_word
