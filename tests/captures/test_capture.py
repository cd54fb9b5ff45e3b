"""Captures: the recorder's file (channels, schemas, metadata, flushing), the decoded view and the reader."""

from __future__ import annotations

import asyncio
import itertools
import json
import shutil
import time
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from manip.captures import Annotator, CaptureError, Recorder, read_capture, read_session, recover
from manip.captures.format import RAW_TOPIC, VIEW_TOPIC, field_schemas, view_schema
from manip.codecs.error_string import ErrorMessage
from manip.codecs.framing import encode_tcp
from manip.codecs.messages import encode_error, request_op
from manip.spec import SPEC
from manip.spec.constants import RequestOp, ServerOp
from tests.support.captures import JOINTS, c2s, record, s2c, session_packets, word
from tests.support.json_schema import validate as _validate

# ------------------------------------------------------------------------------ round trip


def test_round_trip_packets_pairs_and_meaning(tmp_path: Path) -> None:
    path = tmp_path / "s.mcap"
    packets = session_packets()
    record(path, packets)
    session = read_session(path)
    assert [(p.direction, p.packet) for p in session.packets] == packets
    assert [p.time_ns for p in session.packets] == [1_000_000_000 + i * 1000 for i in range(len(packets))]
    kinds = [p.kind for p in session.packets]
    assert kinds == [
        "control", "control", "reply", "request", "reply", "request", "reply", "reply",
        "request", "request", "error", "async", "control", "control",
    ]  # fmt: skip
    by = session.packets
    assert by[4].annotation.fields == {"joints": pytest.approx(JOINTS)}
    assert by[6].annotation.text == "((:A . 1))" and by[6].annotation.final is False
    assert by[7].annotation.final is True
    assert by[9].retransmission and not by[8].retransmission
    assert by[10].annotation.error is not None and by[10].annotation.error["code"] == "NAP"
    assert by[11].annotation.async_ == {
        "condition": 2,
        "condition_name": "segment-completed",
        "word2": 0,
        "word3": 7,
    }
    assert by[11].pair is None
    pairs = session.pairs
    assert [(p.request.op, [r.seq for r in p.replies]) for p in pairs.values()] == [
        ("rfc", [3]),
        ("joint-angles", [5]),
        ("describe-self", [7, 8]),
        ("move", [11]),
    ]
    assert all(p.complete for p in pairs.values())
    assert [r.op for r in session.requests] == ["joint-angles", "describe-self", "move"]
    assert session.contact == "PUMA"
    assert [e.event for e in session.events] == ["rfc", "open", "eof", "cls"]
    assert session.events[-1].fields["reason"] == "Bye"


def test_metadata_header_and_schemas(tmp_path: Path) -> None:
    path = tmp_path / "s.mcap"
    record(path, session_packets())
    with path.open("rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        assert header.profile == "manip" and header.library.startswith("manip ")
        summary = reader.get_summary()
        assert summary is not None
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    info = meta["manip.capture"]
    assert info["spec_revision"] == SPEC.revision
    assert info["seed"] == "7" and info["command_line"] == "test x" and info["tool_version"]
    schemas = {s.name: s for s in summary.schemas.values()}
    raw = json.loads(schemas["manip.ChaosFrame.tcp"].data)
    assert raw["framing"] == "tcp" and raw["spec_revision"] == SPEC.revision and "packet_encoding" in raw
    view = schemas["manip.Packet"]
    assert view.encoding == "jsonschema" and json.loads(view.data)["type"] == "object"
    topics = {c.topic: c for c in summary.channels.values()}
    assert topics["/chaos/c2s"].metadata["framing"] == "tcp"
    assert topics["/manip/s2c"].message_encoding == "json"
    assert summary.statistics is not None
    counts = {summary.channels[cid].topic: n for cid, n in summary.statistics.channel_message_counts.items()}
    assert counts["/chaos/c2s"] == counts["/manip/c2s"] == 6
    assert counts["/chaos/s2c"] == counts["/manip/s2c"] == 8


def test_raw_channel_holds_the_exact_frames(tmp_path: Path) -> None:
    path = tmp_path / "s.mcap"
    packets = session_packets()
    record(path, packets)
    with path.open("rb") as f:
        raw = [
            m.data for _, c, m in make_reader(f).iter_messages(topics=[RAW_TOPIC["c2s"], RAW_TOPIC["s2c"]])
        ]
    assert raw == [encode_tcp(p) for _, p in packets]


def test_frames_that_do_not_decode_are_kept_as_bad_frames(tmp_path: Path) -> None:
    path = tmp_path / "s.mcap"
    good = encode_tcp(c2s(RequestOp.HERE, 2))
    bad = bytearray(good)
    bad[-1] ^= 0xFF  # checksum
    with Recorder(path) as rec:
        link = rec.open_link("tcp")
        rec.frame(link, "c2s", good)
        rec.frame(link, "c2s", bytes(bad))
    capture = read_capture(path)
    assert [p.op for p in capture.sessions[0].packets] == ["here"]
    (bad_frame,) = capture.bad_frames
    assert bad_frame.frame == bytes(bad) and bad_frame.annotation.decode_error is not None


# ------------------------------------------------------------------------------ JSON schema


def test_the_checker_can_fail() -> None:
    with pytest.raises(AssertionError):
        _validate({"link": 1}, view_schema())
    with pytest.raises(AssertionError):
        _validate({"joints": [1.0]}, {"type": "object", "properties": field_schemas()})


def test_every_view_and_event_message_matches_its_json_schema(tmp_path: Path) -> None:
    path = tmp_path / "s.mcap"
    record(path, session_packets())
    seen: set[str] = set()
    with path.open("rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages():
            if channel.message_encoding != "json":
                continue
            assert schema is not None and schema.encoding == "jsonschema"
            _validate(json.loads(message.data), json.loads(schema.data))
            seen.add(channel.topic)
    assert seen == {"/manip/c2s", "/manip/s2c", "/manip/events", "/arm/hand", "/arm/joints"}


def test_view_has_plottable_fields_with_the_frames_times(tmp_path: Path) -> None:
    path = tmp_path / "s.mcap"
    record(path, session_packets())
    with path.open("rb") as f:
        reader = make_reader(f)
        views = {
            m.sequence: (m.log_time, json.loads(m.data))
            for _, _, m in reader.iter_messages(topics=[VIEW_TOPIC["s2c"]])
        }
        raws = {m.sequence: m.log_time for _, _, m in reader.iter_messages(topics=[RAW_TOPIC["s2c"]])}
    assert {s: t for s, (t, _) in views.items()} == raws
    joints = [v for _, v in views.values() if v.get("op") == "joint-angles"]
    assert joints[0]["fields"]["joints"] == pytest.approx(list(JOINTS))
    assert joints[0]["pair"] == 2 and joints[0]["request_number"] == 2


# ------------------------------------------------------------------------------ annotator


def test_a_new_rfc_from_the_same_client_starts_a_new_session() -> None:
    ann = Annotator()
    first = session_packets()
    conns = [ann.annotate(1, d, p).conn for d, p in first]  # type: ignore[arg-type]
    second = [ann.annotate(1, d, p).conn for d, p in first]  # type: ignore[arg-type]
    assert set(conns) == {1} and set(second) == {2}
    assert ann.annotate(2, "c2s", first[0][1]).conn == 3  # the same client on another link


def test_a_reply_to_an_unseen_request_keeps_its_payload() -> None:
    ann = Annotator()
    a = ann.annotate(1, "s2c", s2c(ServerOp.RESPONSE, 9, word(44) + b"\x01\x02"))
    assert a.kind == "reply" and a.pair is None and a.payload_hex == "0102" and a.request_number == 44


def test_a_fatal_error_ends_the_pair_of_the_packet_it_quotes() -> None:
    ann = Annotator()
    req = ann.annotate(1, "c2s", c2s(RequestOp.HERE, 5))
    err = ErrorMessage("dispatch", "F", "BUG", "broken")
    fatal = ann.annotate(1, "s2c", s2c(ServerOp.FATAL_ERROR, 2, encode_error(ServerOp.FATAL_ERROR, 5, err)))
    assert fatal.kind == "error" and fatal.pair == req.pair and fatal.final


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(st.sampled_from(sorted(o.name for o in SPEC.requests.values())), st.integers(0, 3)),
        min_size=1,
        max_size=12,
    )
)
def test_every_request_pairs_with_its_answer_by_position(requests: list[tuple[str, int]]) -> None:
    """Erratum capture-pairing: answers pair in request order; the echoed number is shown, never used to
    re-pair (an echo of another outstanding request's number included)."""
    ann = Annotator()
    pairs = []
    for i, (name, _) in enumerate(requests):
        op = request_op(name)
        req = ann.annotate(1, "c2s", c2s(op.opcode, 10 + i, b""))
        pairs.append(req.pair)
    for i, (_, skew) in enumerate(requests):
        echoed = 10 + (i + skew) % len(requests)  # often another request's number
        reply = ann.annotate(
            1,
            "s2c",
            s2c(
                ServerOp.NON_FATAL_ERROR,
                100 + i,
                encode_error(
                    ServerOp.NON_FATAL_ERROR, echoed, ErrorMessage("x", "C", "BDL", "Bad data length")
                ),
            ),
        )
        assert reply.pair == pairs[i] and reply.request_number == echoed and reply.final
    assert len(set(pairs)) == len(requests)


# ------------------------------------------------------------------------------ durability


def test_chunks_are_written_at_least_once_a_second_while_recording(tmp_path: Path) -> None:
    path = tmp_path / "s.mcap"

    async def run() -> None:
        with Recorder(path, flush_interval=0.5) as rec:
            link = rec.open_link("tcp")
            end = time.monotonic() + 1.8
            n = 0
            while time.monotonic() < end:
                n += 1
                rec.packet(link, "c2s", c2s(RequestOp.HERE, n & 0xFFFF))
                await asyncio.sleep(0.02)

    asyncio.run(run())
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.message_start_time)
    assert len(chunks) >= 3
    for chunk in chunks:
        assert chunk.message_end_time - chunk.message_start_time <= 0.6e9
    gaps = [b.message_start_time - a.message_end_time for a, b in itertools.pairwise(chunks)]
    assert max(gaps) < 0.2e9


def test_an_idle_recorder_writes_its_pending_chunk_within_the_interval(tmp_path: Path) -> None:
    path = tmp_path / "s.mcap"
    snapshot = tmp_path / "snapshot.mcap"

    async def run() -> None:
        with Recorder(path, flush_interval=0.3) as rec:
            link = rec.open_link("tcp")
            rec.packet(link, "c2s", c2s(RequestOp.HERE, 2))
            await asyncio.sleep(0.6)  # nothing else happens: only the timer can flush
            shutil.copy(path, snapshot)

    asyncio.run(run())
    report = recover(snapshot, tmp_path / "fixed.mcap")
    assert not report.complete and report.chunks >= 1
    assert [p.op for p in read_session(tmp_path / "fixed.mcap").packets] == ["here"]


def test_recorder_refuses_unknown_settings(tmp_path: Path) -> None:
    with pytest.raises(CaptureError, match="compression"):
        Recorder(tmp_path / "a.mcap", compression="gzip")
    with Recorder(tmp_path / "b.mcap") as rec, pytest.raises(CaptureError, match="framing"):
        rec.open_link("ethernet")


def test_raw_only_captures_read_the_same(tmp_path: Path) -> None:
    full, raw = tmp_path / "full.mcap", tmp_path / "raw.mcap"
    record(full, session_packets())
    record(raw, session_packets(), decoded_view=False)
    a, b = read_session(full), read_session(raw)
    assert [(p.packet, p.annotation) for p in a.packets] == [(p.packet, p.annotation) for p in b.packets]
    assert raw.stat().st_size < full.stat().st_size
