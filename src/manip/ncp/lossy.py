"""A seeded, lossy, sans-I/O channel for Chaos packets: drops, duplicates, delays, reorders, corrupts.

It stands in for a real link in tests and in the conformance suite.  Nothing here sleeps: ``send`` puts
a packet in flight at time ``now`` and ``deliver(now)`` hands back what has arrived by ``now``, in
arrival order; ``next_delivery_time`` tells a driver when to look again.  All randomness comes from one
``random.Random(seed)``, so a run is reproducible from its seed and its inputs.

Corruption works on :class:`~manip.codecs.packet.Packet` values, below which there are no bytes: it
flips one bit of the data.  On a real link the framing layer's checksum (the CHUDP trailer) catches
corrupted bytes and the frame is dropped, which this channel models as plain loss; ``corrupt`` > 0
models damage that got past the checksum, i.e. a broken peer or link, and is for robustness tests.  An
NCP cannot detect it, so exact-delivery properties do not hold with ``corrupt`` > 0.
"""

from __future__ import annotations

import heapq
import random
from dataclasses import dataclass

from manip.codecs.packet import Packet


@dataclass(slots=True)
class ChannelStats:
    """What the channel did to the packets it was given."""

    sent: int = 0
    dropped: int = 0
    duplicated: int = 0
    reordered: int = 0
    corrupted: int = 0
    delivered: int = 0


class LossyChannel:
    """One direction of an unreliable link.

    ``drop``, ``duplicate``, ``reorder`` and ``corrupt`` are per-packet probabilities.  Each copy of a
    packet that is not dropped arrives after a delay drawn uniformly from ``delay = (lo, hi)`` seconds;
    a reordered copy is held back by an extra 1 to 5 times ``hi`` (at least a millisecond) so that later
    packets overtake it.  A duplicated packet arrives twice, each copy with its own delay."""

    def __init__(
        self,
        seed: int,
        *,
        drop: float = 0.2,
        duplicate: float = 0.05,
        reorder: float = 0.05,
        delay: tuple[float, float] = (0.001, 0.02),
        corrupt: float = 0.0,
    ) -> None:
        for name, p in (("drop", drop), ("duplicate", duplicate), ("reorder", reorder), ("corrupt", corrupt)):
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"{name} is a probability, not {p!r}")
        lo, hi = delay
        if not 0.0 <= lo <= hi:
            raise ValueError(f"delay must be (lo, hi) with 0 <= lo <= hi, not {delay!r}")
        self._rng = random.Random(seed)
        self.drop = drop
        self.duplicate = duplicate
        self.reorder = reorder
        self.delay = (lo, hi)
        self.corrupt = corrupt
        self.stats = ChannelStats()
        self._heap: list[tuple[float, int, Packet]] = []
        self._seq = 0

    def send(self, now: float, packet: Packet) -> None:
        """Put ``packet`` on the channel at time ``now``."""
        rng = self._rng
        self.stats.sent += 1
        if rng.random() < self.drop:
            self.stats.dropped += 1
            return
        copies = 1
        if rng.random() < self.duplicate:
            copies = 2
            self.stats.duplicated += 1
        lo, hi = self.delay
        for _ in range(copies):
            at = now + rng.uniform(lo, hi)
            if rng.random() < self.reorder:
                at += max(hi, 0.001) * rng.uniform(1.0, 5.0)
                self.stats.reordered += 1
            copy = packet
            if copy.data and rng.random() < self.corrupt:
                copy = self._flip(copy)
                self.stats.corrupted += 1
            heapq.heappush(self._heap, (at, self._seq, copy))
            self._seq += 1

    def deliver(self, now: float) -> list[Packet]:
        """The packets that have arrived by ``now``, in arrival order."""
        heap = self._heap
        arrived: list[Packet] = []
        while heap and heap[0][0] <= now:
            arrived.append(heapq.heappop(heap)[2])
        self.stats.delivered += len(arrived)
        return arrived

    def next_delivery_time(self) -> float | None:
        """When the next packet in flight arrives, or None if nothing is in flight."""
        return self._heap[0][0] if self._heap else None

    @property
    def in_flight(self) -> int:
        return len(self._heap)

    def _flip(self, packet: Packet) -> Packet:
        data = bytearray(packet.data)
        bit = self._rng.randrange(len(data) * 8)
        data[bit // 8] ^= 1 << (bit % 8)
        return packet.with_(data=bytes(data))
