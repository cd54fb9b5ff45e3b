"""Hypothesis drives two NCPs over lossy channels and checks the transport's promises after every step.

Invariants: data arrive in order and exactly once; a sender never has more unacknowledged packets than
the receiver's window; and whenever the channel is left to deliver, every controlled packet ends up
receipted (``settle``, also run at teardown).
"""

from __future__ import annotations

import struct

from hypothesis import settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, precondition, rule

from manip.ncp import ConnectionRequested, ConnState, DataReceived, Event, Ncp, Simulation

A, B = 0o401, 0o440
SIDES = st.sampled_from([A, B])


class TwoNcps(RuleBasedStateMachine):
    def __init__(self) -> None:
        super().__init__()
        self.sim: Simulation | None = None
        self.nodes: dict[int, Ncp] = {}
        self.conn: dict[int, int] = {}
        self.windows: dict[int, int] = {}
        self.sent: dict[int, int] = {A: 0, B: 0}
        self.received: dict[int, list[int]] = {A: [], B: []}
        self.auto_read = True
        self.worst_outstanding = 0

    # ------------------------------------------------------------------ plumbing

    def on_event(self, sim: Simulation, node: Ncp, event: Event) -> None:
        if isinstance(event, ConnectionRequested):
            node.accept(sim.now, event.conn_id)
            self.conn[node.address] = event.conn_id
        elif isinstance(event, DataReceived):
            (value,) = struct.unpack("<I", event.data)
            got = self.received[node.address]
            assert value == len(got), f"expected packet {len(got)}, got {value}: out of order or duplicate"
            got.append(value)

    def check_windows(self) -> bool:
        """Called after every simulation step; returns False so that it never stops the run."""
        for side, peer in ((A, B), (B, A)):
            cid = self.conn.get(side)
            if cid is None:
                continue
            info = self.nodes[side].info(cid)
            assert info.outstanding <= self.windows[peer], (side, info)
            self.worst_outstanding = max(self.worst_outstanding, info.outstanding)
        return False

    @property
    def s(self) -> Simulation:
        assert self.sim is not None
        return self.sim

    def read_everything(self, side: int) -> None:
        node, cid = self.nodes[side], self.conn[side]
        if not self.auto_read and node.state(cid) is ConnState.OPEN:
            node.read_ack(self.s.now, cid, node.info(cid).last_received)

    def unreceipted(self) -> int:
        return sum(self.nodes[side].info(self.conn[side]).unreceipted for side in (A, B))

    # ------------------------------------------------------------------ rules

    @initialize(
        seed=st.integers(0, 2**20),
        drop=st.sampled_from([0.0, 0.1, 0.2, 0.3]),
        window_a=st.integers(1, 12),
        window_b=st.integers(1, 12),
        auto_read=st.booleans(),
        first_a=st.integers(0, 0xFFFF),
        first_b=st.integers(0, 0xFFFF),
    )
    def connect(
        self,
        seed: int,
        drop: float,
        window_a: int,
        window_b: int,
        auto_read: bool,
        first_a: int,
        first_b: int,
    ) -> None:
        self.auto_read = auto_read
        self.windows = {A: window_a, B: window_b}
        never = 1e6  # this machine is about data, not timeouts
        a = Ncp(
            A,
            window=window_a,
            first_packet_no=first_a,
            auto_read=auto_read,
            broken_after=never,
            rfc_timeout=never,
        )
        b = Ncp(
            B,
            window=window_b,
            first_packet_no=first_b,
            auto_read=auto_read,
            broken_after=never,
            rfc_timeout=never,
        )
        self.nodes = {A: a, B: b}
        self.sim = Simulation(a, b, seed=seed, drop=drop, duplicate=0.05, reorder=0.05, handler=self.on_event)
        b.listen("HYPO")
        self.conn[A] = a.connect(0.0, B, "HYPO")
        self.s.run_for(
            600.0, stop=lambda: B in self.conn and a.can_send(self.conn[A]) and b.can_send(self.conn[B])
        )
        assert a.can_send(self.conn[A]) and b.can_send(self.conn[B]), "the connection did not open"

    @rule(side=SIDES, n=st.integers(1, 40))
    def send(self, side: int, n: int) -> None:
        node, cid = self.nodes[side], self.conn[side]
        for _ in range(n):
            if not node.can_send(cid):
                break
            node.send(self.s.now, cid, struct.pack("<I", self.sent[side]))
            self.sent[side] += 1
        self.check_windows()

    @rule(dt=st.floats(0.0, 10.0))
    def wait(self, dt: float) -> None:
        self.s.run_for(dt, stop=self.check_windows)

    @precondition(lambda self: not self.auto_read)
    @rule(side=SIDES)
    def read(self, side: int) -> None:
        self.read_everything(side)

    @rule()
    def settle(self) -> None:
        """Let the channel deliver: everything sent must be receipted and delivered."""
        for _ in range(50):
            self.read_everything(A)
            self.read_everything(B)
            if self.s.run_for(30.0, stop=lambda: self.unreceipted() == 0 or self.check_windows()):
                break
        assert self.unreceipted() == 0, [self.nodes[s].info(self.conn[s]) for s in (A, B)]
        assert len(self.received[B]) == self.sent[A]
        assert len(self.received[A]) == self.sent[B]

    # ------------------------------------------------------------------ invariants

    @invariant()
    def delivered_at_most_what_was_sent(self) -> None:
        if self.sim is None:
            return
        assert len(self.received[B]) <= self.sent[A]
        assert len(self.received[A]) <= self.sent[B]

    @invariant()
    def still_open(self) -> None:
        if self.sim is None:
            return
        for side in (A, B):
            assert self.nodes[side].state(self.conn[side]) is ConnState.OPEN

    def teardown(self) -> None:
        if self.sim is not None and self.conn.get(B) is not None:
            self.settle()


TwoNcps.TestCase.settings = settings(max_examples=150, stateful_step_count=50, deadline=None)
TestTwoNcps = TwoNcps.TestCase
