"""Capture benchmark (run by hand): manip's recorder and reader against the raw ``mcap`` writer and reader.

Workload: a session of ``--packets`` TCP-link frames, requests and their replies alternating (here,
joint-angles, set-joint-angles and move with random values, and their transform / joints / segment
replies), made once up front.

Recording, same file settings on both sides (zstd, 256 KiB chunks, CRCs, two schemas, four channels):

* ``manip view``: :meth:`Recorder.frame` per frame, the proxy's path: decode the frame, annotate it,
  write the raw frame and its JSON view.  Baseline ``raw view``: ``mcap.Writer.add_message`` writing
  the very same records: per frame the raw frame on its ``/chaos/*`` channel and the very JSON bytes
  manip wrote (taken from a manip file beforehand) on its ``/manip/*`` channel, with the same times and
  sequence numbers, and after a pose-bearing reply the ``/arm/*`` messages manip wrote for it.  The
  files come out the same size, so the ratio is the price of manip's decoding, annotating, JSON and
  arm poses (kinematics), not of writing more.
* ``manip raw``: the recorder with ``decoded_view=False`` (frames only, still decoded for the
  connection events).  Baseline ``raw frames``: ``mcap.Writer`` writing the frames only.
* ``appender view`` (for information, no target): manip's recorder writes its messages with
  :mod:`manip.captures.appender` (the same bytes as ``add_message``, several times faster); this row is
  that appender writing the premade messages of ``raw view``, i.e. the recorder minus all of its
  decoding, so ``manip view / appender view`` shows manip's own per-frame work undiluted.

Reading the ``manip view`` file: :func:`iter_packets` (every frame decoded and annotated again, the JSON
view skipped) against ``NonSeekingReader.iter_messages(log_time_order=False)`` and ``make_reader``'s
default time-ordered ``iter_messages`` over all messages of the same file.

Rates are frames per second (each frame is one raw message, plus one JSON message with the view) and MB/s
of frame bytes.  Each measurement is the best of ``--trials``, alternating manip and raw.

    .venv/bin/python bench/capture.py [--packets 20000] [--trials 3]

Target: manip at least half the raw rate.  Figures only; nothing is asserted.
"""

from __future__ import annotations

import argparse
import io
import json
import random
import time
from collections.abc import Callable

from mcap.reader import NonSeekingReader, make_reader
from mcap.writer import CompressionType, Writer

from manip.captures import Recorder, iter_packets
from manip.captures.appender import message_adder
from manip.captures.recorder import DEFAULT_CHUNK_SIZE
from manip.codecs.framing import encode_tcp
from manip.codecs.messages import encode_reply, encode_request
from manip.codecs.packet import Packet
from manip.spec.constants import ServerOp

CLIENT = (0o401, 0x0102)
SERVER = (0o440, 0x0304)


def workload(n: int, seed: int = 1985) -> list[tuple[str, bytes]]:
    rng = random.Random(seed)
    frames: list[tuple[str, bytes]] = []

    def floats(k: int) -> tuple[float, ...]:
        return tuple(round(rng.uniform(-180, 180), 3) for _ in range(k))

    number = 2
    while len(frames) < n:
        kind = rng.choice(("here", "joint-angles", "set-joint-angles", "move"))
        if kind == "set-joint-angles":
            data, reply = encode_request(kind, joints=floats(6)), encode_reply(kind, number, segment=number)
        elif kind == "move":
            data, reply = (
                encode_request(kind, transform=floats(12)),
                encode_reply(kind, number, segment=number),
            )
        elif kind == "here":
            data, reply = encode_request(kind), encode_reply(kind, number, transform=floats(12))
        else:
            data, reply = encode_request(kind), encode_reply(kind, number, joints=floats(6))
        opcode = {"here": 0o201, "joint-angles": 0o202, "move": 0o204, "set-joint-angles": 0o215}[kind]
        request = Packet(opcode, SERVER[0], SERVER[1], CLIENT[0], CLIENT[1], number, number - 1, data)
        answer = Packet(ServerOp.RESPONSE, CLIENT[0], CLIENT[1], SERVER[0], SERVER[1], number, number, reply)
        frames.append(("c2s", encode_tcp(request)))
        frames.append(("s2c", encode_tcp(answer)))
        number += 1
    return frames[:n]


def best(trials: int, fns: dict[str, Callable[[], object]]) -> dict[str, float]:
    """Best time of each function over ``trials`` rounds, the functions alternating within a round."""
    times = {name: float("inf") for name in fns}
    for t in range(trials):
        order = list(fns) if t % 2 == 0 else list(reversed(fns))
        for name in order:
            start = time.perf_counter()
            fns[name]()
            times[name] = min(times[name], time.perf_counter() - start)
    return times


T0 = 1_700_000_000_000_000_000
"""Log time of the first frame (ns); frames follow 1 us apart."""


def manip_record(frames: list[tuple[str, bytes]], view: bool) -> bytes:
    """The frames through manip's :class:`Recorder` (the proxy's path), to an in-memory file."""
    out = io.BytesIO()
    rec = Recorder(out, decoded_view=view, command_line=["bench"])
    link = rec.open_link("tcp")
    record = rec.frame
    for i, (direction, frame) in enumerate(frames):
        record(link, direction, frame, T0 + i * 1000)  # type: ignore[arg-type]
    rec.close()
    return out.getvalue()


def views_of(sample: bytes) -> dict[int, bytes]:
    """The JSON view messages of a manip recording, by sequence number (the baseline writes them)."""
    views: dict[int, bytes] = {}
    for _, channel, message in make_reader(io.BytesIO(sample)).iter_messages(log_time_order=False):
        if channel.topic.startswith("/manip/") and channel.topic != "/manip/events":
            views[message.sequence] = message.data
    return views


def arm_of(sample: bytes) -> dict[int, list[tuple[str, bytes, int]]]:
    """The ``/arm/*`` messages of a manip recording (Foxglove pictures of the hand and joints), by log
    time (each frame has its own): the baseline writes them too, so both files hold the same records."""
    arms: dict[int, list[tuple[str, bytes, int]]] = {}
    for _, channel, message in make_reader(io.BytesIO(sample)).iter_messages(log_time_order=False):
        if channel.topic.startswith("/arm/"):
            arms.setdefault(message.log_time, []).append((channel.topic, message.data, message.sequence))
    return arms


def raw_record(
    frames: list[tuple[str, bytes]],
    views: dict[int, bytes],
    view: bool,
    lean: bool = False,
    arms: dict[int, list[tuple[str, bytes, int]]] | None = None,
) -> bytes:
    """The same records through ``mcap.Writer`` (``lean``: through manip's appender instead); with
    ``arms``, the ``/arm/*`` messages after the frames they come from, as the recorder writes them."""
    out = io.BytesIO()
    w = Writer(out, chunk_size=DEFAULT_CHUNK_SIZE, compression=CompressionType.ZSTD)
    w.start(profile="manip", library="bench")
    raw_schema = w.register_schema("frame", "x-manip-frame", b"{}")
    raw = {d: w.register_channel(f"/chaos/{d}", "x-manip-chaos-frame", raw_schema) for d in ("c2s", "s2c")}
    json_schema = w.register_schema("manip.Packet", "jsonschema", json.dumps({"type": "object"}).encode())
    js = {d: w.register_channel(f"/manip/{d}", "json", json_schema) for d in ("c2s", "s2c")}
    arm_schema = w.register_schema("arm", "jsonschema", json.dumps({"type": "object"}).encode())
    arm = {topic: w.register_channel(topic, "json", arm_schema) for topic in ("/arm/hand", "/arm/joints")}
    no_arms: dict[int, list[tuple[str, bytes, int]]] = {}
    arms = arms or no_arms
    if lean:
        one, pair, _ = message_adder(w)
        for i, (direction, frame) in enumerate(frames):
            t = T0 + i * 1000
            pair(raw[direction], frame, js[direction], views[i + 1], t, i + 1)
            for topic, data, seq in arms.get(t, ()):
                one(arm[topic], t, data, seq)
    else:
        add = w.add_message
        for i, (direction, frame) in enumerate(frames):
            t = T0 + i * 1000
            add(raw[direction], t, frame, t, i + 1)
            if view:
                add(js[direction], t, views[i + 1], t, i + 1)
                for topic, data, seq in arms.get(t, ()):
                    add(arm[topic], t, data, t, seq)
    w.finish()  # type: ignore[no-untyped-call]
    return out.getvalue()


def main() -> None:
    parser = argparse.ArgumentParser(description="capture benchmark")
    parser.add_argument("--packets", type=int, default=20000)
    parser.add_argument("--trials", type=int, default=3)
    args = parser.parse_args()
    frames = workload(args.packets)
    frame_bytes = sum(len(f) for _, f in frames)
    sample = manip_record(frames, True)
    views = views_of(sample)
    arms = arm_of(sample)

    n = len(frames)
    print(f"capture benchmark: {n} frames ({frame_bytes / 1e6:.2f} MB of frames), best of {args.trials}")
    rec_times = best(
        args.trials,
        {
            "manip view": lambda: manip_record(frames, True),
            "raw view": lambda: raw_record(frames, views, True, arms=arms),
            "manip raw": lambda: manip_record(frames, False),
            "raw frames": lambda: raw_record(frames, views, False),
            "appender view": lambda: raw_record(frames, views, True, lean=True, arms=arms),
        },
    )
    sizes = {
        "manip view": len(sample),
        "raw view": len(raw_record(frames, views, True, arms=arms)),
        "manip raw": len(manip_record(frames, False)),
    }
    sizes["raw frames"] = len(raw_record(frames, views, False))
    sizes["appender view"] = len(raw_record(frames, views, True, lean=True, arms=arms))
    print("  record                 frames/s      MB/s   file MB")
    for name, seconds in rec_times.items():
        mb_s = frame_bytes / seconds / 1e6
        print(f"    {name:<14} {n / seconds:>12,.0f} {mb_s:>9.2f} {sizes[name] / 1e6:>9.2f}")
    for manip, raw in (("manip view", "raw view"), ("manip raw", "raw frames")):
        ratio = rec_times[raw] / rec_times[manip]
        print(f"    {manip} / {raw}: {ratio:.2f} of raw (target >= 0.5)")
    ratio = rec_times["appender view"] / rec_times["manip view"]
    print(f"    manip view / appender view: {ratio:.2f} (information: the cost of manip's own work)")

    def manip_read() -> int:
        return sum(1 for _ in iter_packets(io.BytesIO(sample)))

    def raw_stream_read() -> int:
        return sum(1 for _ in NonSeekingReader(io.BytesIO(sample)).iter_messages(log_time_order=False))

    def raw_seek_read() -> int:
        return sum(1 for _ in make_reader(io.BytesIO(sample)).iter_messages())

    assert manip_read() == n
    read_times = best(
        args.trials,
        {"manip iter_packets": manip_read, "raw stream": raw_stream_read, "raw time-ordered": raw_seek_read},
    )
    messages = raw_stream_read()
    print(f"  read (the manip view file: {messages} messages, {n} of them frames)")
    print("                           frames/s  messages/s")
    for name, seconds in read_times.items():
        print(f"    {name:<20} {n / seconds:>10,.0f} {messages / seconds:>11,.0f}")
    for raw in ("raw stream", "raw time-ordered"):
        ratio = read_times[raw] / read_times["manip iter_packets"]
        print(f"    manip / {raw}: {ratio:.2f} of raw over the same file (target >= 0.5)")


if __name__ == "__main__":
    main()
