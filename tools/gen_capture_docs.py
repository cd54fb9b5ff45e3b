"""Generate docs/captures.md (the capture file format, its schemas, recovery and replay masks) from the
modules that define them, so the page cannot drift from the code.

Run after changing manip.captures or manip.conformance.replay.masking; tests/captures/test_golden.py
fails while docs/captures.md is stale.
"""

from __future__ import annotations

import importlib
import json
import re
import sys
from pathlib import Path
from types import ModuleType
from typing import Final

from manip.captures import arm_view, pcap, recorder, view
from manip.captures import format as capture_format
from manip.captures.arm_view import (
    FRAME_TRANSFORM_SCHEMA,
    HAND_TOPIC,
    JOINTS_SCHEMA,
    JOINTS_TOPIC,
    frame_transform_schema,
    joints_schema,
)
from manip.captures.format import (
    EVENT_SCHEMA_NAME,
    EVENT_TOPIC,
    RAW_MESSAGE_ENCODING,
    RAW_SCHEMA_ENCODING,
    RAW_SCHEMA_PREFIX,
    RAW_TOPIC,
    VIEW_SCHEMA_NAME,
    VIEW_TOPIC,
    event_schema,
    raw_schema,
    view_schema,
)
from manip.codecs.framing import FRAMINGS
from manip.conformance.replay import masking

TARGET = Path(__file__).resolve().parents[1] / "docs" / "captures.md"
RECOVER: Final = importlib.import_module("manip.captures.recover")
"""The module (``manip.captures.recover`` as an attribute is the function the package exports)."""

_ROLE = re.compile(r":(?:class|func|meth|mod|data|attr):`~?([^`]+)`")


def _markdown(text: str) -> str:
    """A docstring as Markdown: Sphinx roles become code spans, ``literals`` single-backticked, underlined
    titles headings, and definition-list terms (a line whose next is indented) list items."""
    text = _ROLE.sub(lambda m: f"`{m.group(1)}`", text).replace("``", "`")
    lines = text.splitlines()
    out: list[str] = []
    for i, line in enumerate(lines):
        after = lines[i + 1] if i + 1 < len(lines) else ""
        if re.fullmatch(r"=+|-+", line) and out and len(line) == len(out[-1]):
            out[-1] = f"### {out[-1]}"
        elif line and not line[0].isspace() and line[0] not in "*-|" and after.startswith("    "):
            out.append(f"- {line}")
        else:
            out.append(line)
    return "\n".join(out)


def _body(module: ModuleType) -> str:
    """A module docstring without its first line (the title), as Markdown."""
    doc = (module.__doc__ or "").strip().split("\n", 1)
    return _markdown(doc[1].strip() if len(doc) > 1 else "")


def _json_block(value: object) -> list[str]:
    return ["```json", json.dumps(value, indent=2), "```"]


def render() -> str:
    out = [
        "# manip capture files",
        "",
        "Generated from `manip.captures` and `manip.conformance.replay.masking` by "
        "`tools/gen_capture_docs.py`; do not edit by hand.",
        "",
        "## Layout",
        "",
        _body(capture_format),
        "",
        "| topic | message encoding | schema | schema encoding |",
        "|---|---|---|---|",
    ]
    raw = f"`{RAW_MESSAGE_ENCODING}` | `{RAW_SCHEMA_PREFIX}FRAMING` | `{RAW_SCHEMA_ENCODING}`"
    for direction, topic in RAW_TOPIC.items():
        out.append(f"| `{topic}` | {raw} |")
        out.append(f"| `{VIEW_TOPIC[direction]}` | `json` | `{VIEW_SCHEMA_NAME}` | `jsonschema` |")
    out += [
        f"| `{EVENT_TOPIC}` | `json` | `{EVENT_SCHEMA_NAME}` | `jsonschema` |",
        f"| `{HAND_TOPIC}` | `json` | `{FRAME_TRANSFORM_SCHEMA}` | `jsonschema` |",
        f"| `{JOINTS_TOPIC}` | `json` | `{JOINTS_SCHEMA}` | `jsonschema` |",
        "",
        "## Raw frame schemas",
        "",
        "One schema record per framing a capture uses; its data describes the frames:",
        "",
    ]
    for framing in FRAMINGS:
        out += [f"`{RAW_SCHEMA_PREFIX}{framing}`:", "", *_json_block(json.loads(raw_schema(framing))), ""]
    out += [
        "## The decoded view",
        "",
        _body(view),
        "",
        f"`{VIEW_SCHEMA_NAME}`, the JSON Schema of `/manip/c2s` and `/manip/s2c`:",
        "",
        *_json_block(view_schema()),
        "",
        f"`{EVENT_SCHEMA_NAME}`, the JSON Schema of `{EVENT_TOPIC}`:",
        "",
        *_json_block(event_schema()),
        "",
        "## Pictures of the arm",
        "",
        _body(arm_view),
        "",
        f"`{FRAME_TRANSFORM_SCHEMA}` as a capture registers it:",
        "",
        *_json_block(frame_transform_schema()),
        "",
        f"`{JOINTS_SCHEMA}`, the JSON Schema of `{JOINTS_TOPIC}`:",
        "",
        *_json_block(joints_schema()),
        "",
        "## Writing",
        "",
        _body(recorder),
        "",
        "## Recovering a cut file",
        "",
        _body(RECOVER),
        "",
        "## pcap and pcapng",
        "",
        _body(pcap),
        "",
        "## What replay compares",
        "",
        _body(masking),
        "",
    ]
    return "\n".join(out)


def main() -> None:
    TARGET.write_text(render())
    print(f"wrote {TARGET}", file=sys.stderr)


if __name__ == "__main__":
    main()
