"""A readable listing of a capture (``manip-capture info``): header, channels, sessions, one line a packet;
and the same as one JSON document (``--json``), each packet as its decoded view."""

from __future__ import annotations

import json
import os
import time
from collections.abc import Iterator
from typing import Any

from manip.spec import SPEC

from .reader import Capture, CapturedEvent, CapturedPacket, Session
from .view import view_bytes


def _value(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, (tuple, list)):
        return "(" + ", ".join(_value(x) for x in v) + ")"
    if isinstance(v, str):
        return repr(v)
    return str(v)


def _fields(fields: dict[str, Any] | None) -> str:
    return " ".join(f"{k}={_value(v)}" for k, v in (fields or {}).items())


def packet_line(p: CapturedPacket, t0_ns: int) -> str:
    """One line for a packet: time from ``t0_ns``, direction, link, connection, then its meaning."""
    a = p.annotation
    head = f"{(p.time_ns - t0_ns) / 1e9:11.6f}  {p.direction}  L{p.link} C{a.conn}"
    if p.packet is None:
        message = (a.decode_error or {}).get("message", "?")
        return f"{head}  bad frame ({len(p.frame)} bytes): {message}"
    pk = p.packet
    head += f"  #{pk.packet_no:<5d} {SPEC.chaos_opcode_name(pk.opcode):<3}"
    match a.kind:
        case "request":
            body = f"request {a.op or f'0{pk.opcode:o}'} {_fields(a.fields)}"
        case "reply":
            if a.fields:
                rest = _fields(a.fields)
            elif a.text is not None:
                rest = repr(a.text if len(a.text) <= 60 else a.text[:57] + "...")
            elif a.payload_hex:
                rest = f"data {a.payload_hex}"
            else:
                spec_op = next((o for o in SPEC.requests.values() if o.name == a.op), None)
                kind = spec_op.response.form if spec_op is not None else None
                rest = {"multi": "(end)", "done": "done"}.get(kind or "", "")
            body = f"reply to #{a.request_number} ({a.op or 'unknown request'}) {rest}"
        case "error":
            server = SPEC.server_opcodes.get(pk.opcode)
            rendered = (a.error or {}).get("rendered", "")
            body = f"{server.name if server else 'error'} #{a.request_number}: {rendered}"
        case "async":
            info = a.async_ or {}
            body = (
                f"async #{a.request_number} {info.get('condition_name', '?')} "
                f"word2={info.get('word2')} word3={info.get('word3')}"
            )
        case "control":
            body = repr(a.text) if a.text else ""
        case _:
            body = f"{a.kind} {a.payload_hex or ''}"
    if a.decode_error is not None:
        body += f"  !! {a.decode_error['message']}"
    if a.pair is not None:
        body += f"  [pair {a.pair}]"
    if a.retransmission:
        body += "  (retransmission)"
    return f"{head} {body}".rstrip()


def when(ns: int) -> str:
    """A capture time for people: UTC date and time to the microsecond (never a raw epoch)."""
    seconds, rest = divmod(ns, 1_000_000_000)
    return time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(seconds)) + f".{rest // 1000:06d}Z"


def _session_events(events: list[CapturedEvent]) -> str:
    return ", ".join(
        f"{e.event}({e.fields['reason']!r})" if "reason" in e.fields else e.event for e in events
    )


def _session_summary(s: Session) -> dict[str, Any]:
    """What the listing says of a session, for the text and the JSON alike."""
    c2s = len(s.client_packets)
    pairs = s.pairs
    return {
        "conn": s.conn,
        "link": s.link,
        "contact": s.contact,
        "packets": len(s.packets),
        "c2s": c2s,
        "s2c": len(s.packets) - c2s,
        "requests": len(s.requests),
        "pairs": len(pairs),
        "answered": sum(1 for p in pairs.values() if p.complete),
    }


def _event_json(e: CapturedEvent) -> dict[str, Any]:
    return {"time_ns": e.time_ns, "event": e.event, **e.fields}


def packet_view(p: CapturedPacket) -> dict[str, Any]:
    """A packet as the ``/manip/c2s|s2c`` view holds it, with its time."""
    nbytes = len(p.packet.data) if p.packet is not None else len(p.frame)
    view: dict[str, Any] = json.loads(view_bytes(p.annotation, p.link, p.direction, p.seq, p.packet, nbytes))
    return {"time_ns": p.time_ns, **view}


def info_json(capture: Capture, *, packets: bool = True) -> dict[str, Any]:
    """The ``manip-capture info --json`` document: what :func:`info_lines` lists, as data."""
    sessions = [
        {**_session_summary(s), "events": [_event_json(e) for e in s.events]} for s in capture.sessions
    ]
    out: dict[str, Any] = {
        "capture": capture.path,
        "bytes": os.path.getsize(capture.path) if os.path.exists(capture.path) else 0,
        "profile": capture.profile,
        "library": capture.library,
        "metadata": capture.metadata,
        "start_ns": capture.start_ns,
        "end_ns": capture.end_ns,
        "start": when(capture.start_ns),
        "end": when(capture.end_ns),
        "channels": dict(sorted(capture.counts.items())),
        "links": [{"id": k.id, "framing": k.framing, "name": k.name} for k in capture.links.values()],
        "events": [_event_json(e) for e in capture.events],
        "sessions": sessions,
        "bad_frames": len(capture.bad_frames),
    }
    if packets:
        out["packets"] = [packet_view(p) for p in [*capture.packets, *capture.bad_frames]]
    return out


def info_lines(capture: Capture, *, packets: bool = True) -> Iterator[str]:
    """The ``manip-capture info`` listing."""
    size = os.path.getsize(capture.path) if os.path.exists(capture.path) else 0
    yield f"capture {capture.path} ({size} bytes), profile {capture.profile!r}, library {capture.library!r}"
    for name, meta in capture.metadata.items():
        yield f"metadata {name}:"
        for key, value in meta.items():
            yield f"  {key}: {value}"
    start, end = capture.start_ns, capture.end_ns
    yield f"time span: {when(start)} .. {when(end)} ({(end - start) / 1e9:.3f} s)"
    yield "channels:"
    for topic, count in sorted(capture.counts.items()):
        yield f"  {topic:<16} {count:>8} messages"
    yield "links:"
    for link in capture.links.values():
        yield f"  L{link.id} {link.framing} {link.name}"
    for event in capture.events:
        detail = " ".join(f"{k}={v}" for k, v in event.fields.items())
        yield f"  {(event.time_ns - start) / 1e9:11.6f}  {event.event} {detail}".rstrip()
    yield f"sessions: {len(capture.sessions)}"
    for s in capture.sessions:
        n = _session_summary(s)
        yield (
            f"  C{n['conn']} on L{n['link']}, contact {n['contact']!r}: {n['packets']} packets "
            f"({n['c2s']} c2s, {n['s2c']} s2c), {n['requests']} requests, "
            f"{n['pairs']} pairs ({n['answered']} answered); {_session_events(s.events)}"
        )
    if capture.bad_frames:
        yield f"bad frames: {len(capture.bad_frames)}"
    if packets:
        yield "packets:"
        for p in capture.packets:
            yield "  " + packet_line(p, start)
        for p in capture.bad_frames:
            yield "  " + packet_line(p, start)
