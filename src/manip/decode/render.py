"""Print a decoded tree as indented text, JSON, or an annotated hex dump."""

from __future__ import annotations

import json
from collections.abc import Iterator

from manip.decode.describe import Node

HEADER_BYTES = 16


def render_tree(node: Node, indent: int = 0) -> str:
    return "\n".join(_tree_lines(node, indent))


def _tree_lines(node: Node, indent: int) -> Iterator[str]:
    pad = "  " * indent
    where = f"  @{node.offset}+{node.size}" if node.offset is not None and node.size else ""
    yield f"{pad}{node.label}: {node.text}{where}" if node.text else f"{pad}{node.label}{where}"
    for child in node.children:
        yield from _tree_lines(child, indent + 1)


def render_json(nodes: list[Node]) -> str:
    return json.dumps([n.to_json() for n in nodes], indent=2)


def render_hexdump(packet_bytes: bytes, node: Node, *, width: int = 16) -> str:
    """The packet in PDP-11 memory order (header, then data), then each field beside its byte range."""
    lines = [
        f"{i:04x}  {packet_bytes[i : i + width].hex(' '):<{3 * width}}"
        for i in range(0, len(packet_bytes), width)
    ]
    lines.append("")
    for section in node.children:
        base = 0 if section.label == "chaos header" else HEADER_BYTES
        for leaf in _leaves(section):
            if leaf.offset is not None and leaf.size:
                start = base + leaf.offset
                span = f"{start:04x}-{start + leaf.size - 1:04x}"
                lines.append(f"  {span}  {section.label:<20} {leaf.label:<16} {leaf.text}")
    return "\n".join(lines)


def _leaves(node: Node) -> Iterator[Node]:
    if not node.children:
        yield node
    for child in node.children:
        yield from _leaves(child)
