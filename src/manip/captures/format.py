"""What a manip capture file holds: topics, encodings, schemas and metadata names (the file format).

A capture is an MCAP file (profile ``manip``), chunked and zstd-compressed, with these channels:

``/chaos/c2s``, ``/chaos/s2c`` (message encoding ``x-manip-chaos-frame``)
    The source of truth: every frame that crossed one link in one direction, byte for byte in that
    link's framing (``tcp``, ``chudp``, ``chaosd``; :mod:`manip.codecs.framing`).  One channel per link
    and direction; its metadata name the link (``link`` id, ``framing``, ``name``, ``direction``).  The
    schema record (encoding ``x-manip-frame``, one per framing) is a small JSON document naming the
    framing, the spec revision and the packet encoding, so the file explains itself.
``/manip/c2s``, ``/manip/s2c`` (``json``, schema ``manip.Packet`` in ``jsonschema``)
    The same packets decoded: Chaos header, then the manip meaning (request name and fields, reply
    fields, parsed error strings, asynchronous conditions), the connection and the pair id that ties a
    request to its replies.  Each decoded message has the ``log_time`` and ``sequence`` of its frame.
    Foxglove lists and plots these fields (``/manip/s2c.fields.joints[0]``).  Field floats were PDP-11
    singles on the wire and are written with nine significant digits, which name each exactly
    (``-131.628876``, not the double's ``-131.62887573242188``); a whole one keeps its point (``1.0``).
``/manip/events`` (``json``, schema ``manip.Event``)
    Link and connection events: link opened or closed (with the reason), RFC, OPN, CLS and LOS with
    their texts, EOF, framing lost, recording started and stopped.
``/arm/hand`` (``json``, schema ``foxglove.FrameTransform``), ``/arm/joints`` (``manip.JointAngles``)
    The hand's pose after every ``here`` and ``joint-angles`` reply, world to hand in Foxglove's
    well-known schema, and the joint angles of every ``joint-angles`` reply as six plottable numbers
    (:mod:`manip.captures.arm_view`); written with the decoded view, on a capture's first such reply.

``c2s`` is client to server (requests), ``s2c`` server to client.  Times are Unix nanoseconds of the
moment the recorder saw the frame; a simulated run (``manip-conform run --record``, ``time`` ``virtual``)
records its virtual clock anchored at the wall-clock start of the recording, and keeps both origins
(``wall_origin_ns``, ``virtual_origin_ns``) so that a replay puts each request at its virtual instant.
Metadata record ``manip.capture``: tool and version, spec revision, seed, command line, how it was
recorded.
"""

from __future__ import annotations

import json
from functools import cache
from typing import Any, Final

from manip.codecs.framing import FRAMINGS
from manip.codecs.packet import Direction
from manip.spec import SPEC, FieldType

DIRECTIONS: Final[tuple[Direction, Direction]] = ("c2s", "s2c")

PROFILE: Final = "manip"
METADATA_NAME: Final = "manip.capture"
RECOVERY_METADATA_NAME: Final = "manip.recovery"

RAW_TOPIC: Final[dict[Direction, str]] = {"c2s": "/chaos/c2s", "s2c": "/chaos/s2c"}
VIEW_TOPIC: Final[dict[Direction, str]] = {"c2s": "/manip/c2s", "s2c": "/manip/s2c"}
EVENT_TOPIC: Final = "/manip/events"

RAW_MESSAGE_ENCODING: Final = "x-manip-chaos-frame"
RAW_SCHEMA_ENCODING: Final = "x-manip-frame"
RAW_SCHEMA_PREFIX: Final = "manip.ChaosFrame."
VIEW_SCHEMA_NAME: Final = "manip.Packet"
EVENT_SCHEMA_NAME: Final = "manip.Event"

PACKET_ENCODING: Final = (
    "Chaos packet (manip.codecs.chaos): eight 16-bit header words (opcode<<8, fc<<12|nbytes, dest host, "
    "dest index, src host, src index, packet number, ack number), nbytes of data padded to a word, then "
    "the hardware trailer (dest, source, checksum) where the framing has one; word byte order and "
    "delimiting as the framing says"
)
KINDS: Final = (
    "request",
    "reply",
    "error",
    "async",
    "control",
    "data",
    "bad-frame",
)
"""The ``kind`` of a decoded packet: a manip request, a RESPONSE, an error packet (0201/0202, or an
asynchronous 0204/0205 error), an asynchronous response (0203), a Chaos control packet, other data, or a
frame that did not decode."""


def raw_schema(framing: str) -> bytes:
    """The schema record data of raw frames in ``framing``."""
    return json.dumps(
        {
            "framing": framing,
            "framing_description": FRAMINGS[framing].description,
            "spec_revision": SPEC.revision,
            "protocol_version": SPEC.protocol_version,
            "packet_encoding": PACKET_ENCODING,
        },
        indent=1,
    ).encode()


def _field_schema(ft: FieldType) -> dict[str, Any]:
    match ft.element:
        case "float":
            item: dict[str, Any] = {"type": "number"}
        case "text":
            return {"type": "string"}
        case "counted":
            return {"type": "array", "items": {"type": "integer"}}
        case _:
            item = {"type": "integer"}
    if ft.count == 1:
        return item
    return {"type": "array", "items": item, "minItems": ft.count, "maxItems": ft.count}


@cache
def field_schemas() -> dict[str, dict[str, Any]]:
    """Every request and response field of the spec by name (each name has one type in the spec)."""
    fields: dict[str, dict[str, Any]] = {}
    for op in SPEC.requests.values():
        for f in (*op.request.fields, *op.response.data.fields):
            fields.setdefault(f.name, _field_schema(f.type))
    fields.setdefault("segment", {"type": "integer"})
    return fields


_INT: Final = {"type": "integer"}
_STR: Final = {"type": "string"}


@cache
def view_schema() -> dict[str, Any]:
    """JSON Schema of the decoded view (``/manip/c2s`` and ``/manip/s2c``)."""
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": VIEW_SCHEMA_NAME,
        "description": f"A Chaos packet of the manip protocol, decoded ({SPEC.revision})",
        "type": "object",
        "properties": {
            "link": _INT,
            "conn": _INT,
            "direction": {"type": "string", "enum": list(DIRECTIONS)},
            "seq": _INT,
            "opcode": _INT,
            "opcode_name": _STR,
            "src_host": _INT,
            "src_index": _INT,
            "dest_host": _INT,
            "dest_index": _INT,
            "packet_no": _INT,
            "ack_no": _INT,
            "nbytes": _INT,
            "kind": {"type": "string", "enum": list(KINDS)},
            "retransmission": {"type": "boolean"},
            "op": {"type": "string", "description": "manip request name (also on its replies)"},
            "request_number": _INT,
            "pair": {"type": "integer", "description": "ties a request to its replies"},
            "final": {"type": "boolean", "description": "the last reply of its pair"},
            "fields": {"type": "object", "properties": field_schemas(), "additionalProperties": False},
            "text": _STR,
            "error": {
                "type": "object",
                "properties": {
                    "where": _STR,
                    "severity": _STR,
                    "code": _STR,
                    "message": _STR,
                    "args": {"type": "array", "items": _INT},
                    "rendered": _STR,
                    "problems": {"type": "array", "items": _STR},
                },
                "required": ["where", "severity", "code", "message", "rendered"],
                "additionalProperties": False,
            },
            "async": {
                "type": "object",
                "properties": {"condition": _INT, "condition_name": _STR, "word2": _INT, "word3": _INT},
                "required": ["condition", "condition_name", "word2", "word3"],
                "additionalProperties": False,
            },
            "payload_hex": _STR,
            "decode_error": {
                "type": "object",
                "properties": {"message": _STR, "path": _STR, "offset": _INT, "clause": _STR},
                "required": ["message"],
                "additionalProperties": False,
            },
        },
        "required": ["link", "conn", "direction", "seq", "kind", "nbytes"],
        "additionalProperties": False,
    }


@cache
def event_schema() -> dict[str, Any]:
    """JSON Schema of ``/manip/events``."""
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": EVENT_SCHEMA_NAME,
        "type": "object",
        "properties": {
            "event": {
                "type": "string",
                "enum": [
                    "recording-started",
                    "recording-stopped",
                    "link-open",
                    "link-closed",
                    "framing-lost",
                    "rfc",
                    "open",
                    "refused",
                    "cls",
                    "los",
                    "eof",
                    "ans",
                    "fwd",
                ],
            },
            "link": _INT,
            "conn": _INT,
            "direction": {"type": "string", "enum": list(DIRECTIONS)},
            "reason": _STR,
            "name": _STR,
            "framing": _STR,
            "contact": _STR,
            "args": _STR,
        },
        "required": ["event"],
        "additionalProperties": False,
    }
