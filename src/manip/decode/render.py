"""Print a decoded tree as indented text, JSON, or an annotated hex dump."""

from __future__ import annotations

from collections.abc import Iterator

from manip.decode.describe import TreeNode

HEADER_BYTES = 16


def render_tree(node: TreeNode, indent: int = 0) -> str:
    lines: list[str] = []
    _tree_lines(node, indent, lines)
    return "\n".join(lines)


def _tree_lines(node: TreeNode, indent: int, lines: list[str]) -> None:
    # Appends to one list (no generator per level): this runs for every node of every packet.
    pad = "  " * indent
    where = f"  @{node.offset}+{node.size}" if node.offset is not None and node.size else ""
    lines.append(f"{pad}{node.label}: {node.text}{where}" if node.text else f"{pad}{node.label}{where}")
    for child in node.children:
        _tree_lines(child, indent + 1, lines)


def _span(first: int, size: int, region: int, msb_first: bool) -> tuple[int, int]:
    """Wire offsets of natural bytes ``first .. first+size-1`` of a region of 16-bit words starting at
    ``region``: with the most significant byte first the two bytes of each word trade places."""
    at = [region + (j ^ 1 if msb_first else j) for j in range(first, first + size)]
    return min(at), max(at)


def render_hexdump(
    wire: bytes,
    node: TreeNode,
    *,
    start: int = 0,
    base: int = 0,
    msb_first: bool = False,
    trailer: bool = False,
    note: str = "",
    origin: str = "the start of the input",
    width: int = 16,
) -> str:
    """The bytes exactly as they were on the wire, offsets counted from ``origin`` (``wire`` begins at
    ``start``), then each field beside the wire bytes that hold it.

    ``base`` is where the Chaos header begins within ``wire``, ``msb_first`` the word byte order,
    ``trailer`` whether the hardware trailer follows the data.  ``base`` -1 means ``wire`` is a bare
    body (the data of a packet, natural order).
    """
    digits = max(4, len(f"{start + len(wire):x}"))
    lines = [f"wire order ({note}); offsets are from {origin}" if note else f"offsets are from {origin}"]
    lines += [f"{start + i:0{digits}x}  {wire[i : i + width].hex(' ')}" for i in range(0, len(wire), width)]
    lines.append("")
    fields: list[tuple[int, int, str]] = []

    def line(lo: int, hi: int, section: str, label: str, text: str) -> None:
        span = f"{start + lo:0{digits}x}-{start + hi:0{digits}x}"
        fields.append((lo, len(fields), f"  {span}  {section:<20} {label:<16} {text}".rstrip()))

    if base > 0:
        line(0, base - 1, "frame", "framing header", wire[:base].hex(" "))
    data_start = 0 if base < 0 else base + HEADER_BYTES
    for section in node.children:
        header = section.label == "chaos header"
        region = base if header else data_start
        for leaf in _leaves(section):
            if leaf.offset is not None and leaf.size:
                lo, hi = _span(leaf.offset, leaf.size, region, msb_first and base >= 0)
                line(lo, hi, section.label, leaf.label, leaf.text)
            elif header and leaf.label == "trailer" and trailer:
                at = len(wire) - 6  # the trailer ends the frame
                line(at, at + 5, section.label, "trailer", leaf.text)
    return "\n".join(lines + [text for _, _, text in sorted(fields)])


def _leaves(node: TreeNode) -> Iterator[TreeNode]:
    if not node.children:
        yield node
    for child in node.children:
        yield from _leaves(child)
