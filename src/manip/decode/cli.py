"""``manip-decode``: show what a packet (or a Cougar word stream) means, field by field.

Output is streamed: each packet is printed as soon as its frame is complete, so the first line comes at
once and memory stays flat whatever the size of the input (a JSON array is written element by
element, one packet a line).  Exit status: 0 decoded; 1 the input is malformed or empty (the message
says what, where and which clause) or a filter selects nothing; 2 usage error (a missing file among
them).
"""

from __future__ import annotations

import json
import os
import re
import sys
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any, Final

import click

from manip.codecs.cougar import WordStream
from manip.codecs.errors import DecodeError
from manip.codecs.framing import FRAMINGS
from manip.codecs.messages import request_op
from manip.codecs.packet import Packet
from manip.commandline import configure_logging, version_option
from manip.decode.describe import (
    ReadAs,
    TreeNode,
    describe_body,
    describe_packet,
    describe_words,
    packet_json,
)
from manip.decode.frames import LAYOUTS, EmptyInputError, Frame, FrameLayout, frames
from manip.decode.pairing import StreamPairing
from manip.decode.render import render_hexdump, render_tree
from manip.decode.source import (
    SourceError,
    byte_blocks,
    open_source,
    read_text,
    require_file,
    terminal_prompt,
)
from manip.exit_status import epilog
from manip.spec import SPEC
from manip.spec.constants import ChaosOp
from manip.spec.notation import octal

_SERVER_NAMES: Final = {s.name: s.opcode for s in SPEC.server_opcodes.values()}
_JSON: Final = json.JSONEncoder(separators=(",", ":")).encode
_WORDS: Final = re.compile(r"^[\s,0-9a-fA-FxXoObB]+$")


def _parse_words(text: str) -> list[int]:
    words = []
    for token in re.split(r"[\s,]+", text.strip()):
        if not token:
            continue
        try:
            value = int(token, 0) if token[:2].lower() in ("0o", "0x", "0b") else int(token, 16)
        except ValueError:
            raise click.BadParameter(f"{token!r} is not a word (hex, or 0o/0x prefixed)") from None
        if not 0 <= value <= 0xFFFF:
            raise click.BadParameter(f"{token!r} does not fit in 16 bits")
        words.append(value)
    return words


def _opcode_key(value: str) -> int | str:
    """An opcode as typed: octal digits (``201``, ``0201``) are a number, anything else a name."""
    return int(value, 8) if value.isdigit() and set(value) <= set("01234567") else value


def _request_key(value: str | None) -> int | str | None:
    if value is None:
        return None
    key = _opcode_key(value)
    try:
        request_op(key)
    except KeyError as exc:
        raise click.BadParameter(str(exc.args[0]), param_hint="--request-opcode") from None
    return key


# ---------------------------------------------------------------------------------------- filters


@dataclass(frozen=True, slots=True)
class _OpFilter:
    opcode: int
    name: str | None = None
    """A request name: in a capture, its requests and the replies to them."""
    direction: str | None = None


@dataclass(frozen=True, slots=True)
class Filters:
    """``--filter`` terms: alternatives of one key are or-ed, different keys and-ed."""

    ops: tuple[_OpFilter, ...] = ()
    conns: tuple[int, ...] = ()

    def wants(self, opcode: int | None, *, op: str | None = None, direction: str | None = None) -> bool:
        if not self.ops:
            return True
        for f in self.ops:
            if f.name is not None and op is not None:
                if op == f.name:
                    return True
                continue
            if opcode == f.opcode and (f.direction is None or direction is None or direction == f.direction):
                return True
        return False

    def wants_conn(self, conn: int) -> bool:
        return not self.conns or conn in self.conns


def _parse_filters(terms: tuple[str, ...]) -> Filters:
    ops: list[_OpFilter] = []
    conns: list[int] = []
    for term in terms:
        key, sep, value = term.partition("=")
        if not sep or not value:
            raise click.BadParameter(f"{term!r}: use opcode=OP or conn=N", param_hint="--filter")
        if key == "conn":
            if not value.isdigit():
                raise click.BadParameter(
                    f"{term!r}: a connection is a number (C1 is 1)", param_hint="--filter"
                )
            conns.append(int(value))
        elif key == "opcode":
            ops.append(_op_filter(value))
        else:
            raise click.BadParameter(f"{term!r}: filter on opcode= or conn=", param_hint="--filter")
    return Filters(tuple(ops), tuple(conns))


def _op_filter(value: str) -> _OpFilter:
    key = _opcode_key(value)
    if isinstance(key, int):
        if not 0 <= key <= 0o377:
            raise click.BadParameter(f"opcode {octal(key)} does not fit in a byte", param_hint="--filter")
        return _OpFilter(key)
    if key in _SERVER_NAMES:
        return _OpFilter(_SERVER_NAMES[key], direction="s2c")
    upper = key.upper()
    if upper in ChaosOp.__members__:
        return _OpFilter(ChaosOp[upper])
    try:
        op = request_op(key)
    except KeyError:
        raise click.BadParameter(
            f"{value!r} is not an opcode: give it in octal (0204), or name a request (move), a server "
            "opcode (non-fatal-error) or a Chaos opcode (RFC, OPN, CLS, STS...)",
            param_hint="--filter",
        ) from None
    return _OpFilter(op.opcode, op.name, "c2s")


# ---------------------------------------------------------------------------------------- output


class _Out:
    """Writes packets as they come: trees separated by blank lines, or one JSON array.

    Straight to ``sys.stdout`` (what ``click.echo`` would do for plain text, without its per-call cost,
    which is a fifth of the decoder's time on a long stream); never coloured, never wrapped."""

    def __init__(self, fmt: str) -> None:
        self.fmt = fmt
        self.count = 0
        self.write = sys.stdout.write

    def node(
        self,
        node: TreeNode,
        *,
        hexdump: Callable[[], str] | None = None,
        line: str | None = None,
        headless: Packet | None = None,
    ) -> None:
        """``headless``: ``node`` was described without its Chaos header, which is this packet's."""
        parts = []
        if self.fmt == "json":
            parts.append("[\n" if not self.count else ",\n")
            # one packet a line: compact, and C-encoded
            parts.append(_JSON(node.to_json()) if headless is None else packet_json(node, headless))
        else:
            if self.count:
                parts.append("\n")
            if line is not None:
                parts.append(line + "\n")
            if self.fmt == "hexdump" and hexdump is not None:
                parts.append(hexdump() + "\n")
            else:
                parts.append(render_tree(node, 1 if line is not None else 0) + "\n")
        self.write("".join(parts))
        self.count += 1

    def text(self, line: str) -> None:
        """A line that is not a packet (never in JSON, whose output must stay one document)."""
        if self.fmt != "json":
            self.write(line + "\n")

    def close(self) -> None:
        if self.fmt == "json":
            self.write("\n]\n" if self.count else "[]\n")
        sys.stdout.flush()


def _failed(node: TreeNode) -> bool:
    return any(c.label == "decode error" for c in node.children)


def _error_node(frame: Frame, err: DecodeError, link: str) -> TreeNode:
    node = TreeNode("frame", f"{link} frame at byte {frame.offset}, {len(frame.wire)} bytes, does not decode")
    node.add(
        "decode error",
        str(err),
        {"message": err.message, "path": err.path, "offset": err.offset, "clause": err.clause},
    )
    return node


# ---------------------------------------------------------------------------------------- command


@click.command(
    context_settings={"help_option_names": ["-h", "--help"], "show_default": True},
    epilog=epilog("manip-decode"),
)
@click.argument("source", required=False)
@click.option(
    "--link", type=click.Choice(sorted(FRAMINGS)), default="chudp", help="Framing of the input bytes."
)
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["tree", "json", "hexdump"]),
    default="tree",
    help="hexdump: the bytes in wire order, offsets from the start of the input, each field beside "
    "its bytes.",
)
@click.option(
    "--direction",
    type=click.Choice(["auto", "request", "response"]),
    default="auto",
    help="Requests and server packets share opcodes 0200-0205; auto guesses from the data.",
)
@click.option(
    "--request-opcode",
    "request",
    metavar="OP",
    help="For a response: the request it answers (octal number like 201, or a name like here).",
)
@click.option(
    "--body",
    nargs=2,
    metavar="request|response OP",
    default=None,
    help="SOURCE is a bare body (packet data, no Chaos header), as in the golden vectors: a request of "
    "opcode OP, or a response to request OP (or to a server opcode by name: non-fatal-error...).",
)
@click.option(
    "--cougar",
    type=click.Choice(["command", "response"]),
    default=None,
    help="Decode a Cougar word stream (hex words) as Puma commands or Cougar responses.",
)
@click.option("--binary/--hex", "binary", default=None, help="How to read a SOURCE file (default: guess).")
@click.option("--mcap", metavar="FILE", default=None, help="Decode every packet of a manip capture instead.")
@click.option(
    "--pcap",
    metavar="FILE",
    default=None,
    help="Decode the CHUDP datagrams of a tcpdump or Wireshark capture (pcap or pcapng) instead.",
)
@click.option(
    "--port",
    "ports",
    type=click.IntRange(0, 65535),
    multiple=True,
    help="With --pcap: only UDP datagrams from or to this port (repeatable; default: any that look "
    "like CHUDP).",
)
@click.option(
    "--filter",
    "filter_terms",
    metavar="KEY=VALUE",
    multiple=True,
    help="Only packets with opcode=OP (octal, or a request, server or Chaos opcode name; in a capture a "
    "request name also selects its replies) or, in a capture, of connection conn=N. Repeatable.",
)
@version_option("manip-decode")
def main(
    source: str | None,
    link: str,
    fmt: str,
    direction: ReadAs,
    request: str | None,
    body: tuple[str, str] | None,
    cougar: str | None,
    binary: bool | None,
    mcap: str | None,
    pcap: str | None,
    ports: tuple[int, ...],
    filter_terms: tuple[str, ...],
) -> None:
    """Decode SOURCE: a hex string, a file, or - for standard input (the default)."""
    configure_logging()
    filters = _parse_filters(filter_terms)
    if ports and pcap is None:
        raise click.UsageError("--port goes with --pcap")
    if filters.conns and mcap is None and pcap is None:
        raise click.UsageError("--filter conn=N needs --mcap or --pcap: only captures number connections")
    try:
        if mcap is not None or pcap is not None:
            if mcap is not None and pcap is not None:
                raise click.UsageError("give --mcap or --pcap, not both")
            if source is not None:
                raise click.UsageError(f"--{'mcap' if mcap else 'pcap'} takes no SOURCE")
            sys.exit(_decode_capture(mcap, pcap, ports, fmt, filters))
        prompt = terminal_prompt(source)
        if prompt is not None:
            click.echo(prompt, err=True)
        if cougar is not None:
            sys.exit(_decode_cougar(source, cougar, fmt))
        if body is not None:
            sys.exit(_decode_body(body, source, binary, fmt))
        sys.exit(_decode_packets(source, link, binary, fmt, direction, _request_key(request), filters))
    except SourceError as exc:
        click.echo(f"manip-decode: {exc}", err=True)
        sys.exit(2 if exc.usage else 1)


def _decode_packets(
    source: str | None,
    link: str,
    binary: bool | None,
    fmt: str,
    direction: ReadAs,
    request: int | str | None,
    filters: Filters,
) -> int:
    src = open_source(source)
    out = _Out(fmt)
    json_out = fmt == "json"
    layout = LAYOUTS[link]
    failed = 0
    bad = 0
    pairing = StreamPairing() if request is None and link in _STREAMS else None
    try:
        for frame in frames(byte_blocks(src, binary), link):
            if frame.packet is not None and not filters.wants(frame.packet.opcode):
                continue
            if frame.packet is None:
                assert frame.error is not None
                if link in ("chudp", "raw"):  # one packet, and it did not decode: the message says all
                    out.close()
                    click.echo(f"manip-decode: malformed {link} input: {frame.error}", err=True)
                    return 1
                bad += 1
                out.node(_error_node(frame, frame.error, link))
                continue
            packet = frame.packet
            node = _describe_paired(packet, direction, request, pairing, header=not json_out)
            if frame.error is not None:
                node.add("decode error", str(frame.error))
            failed += _failed(node) or frame.error is not None
            if json_out:
                out.node(node, headless=packet)
            else:
                out.node(node, hexdump=_dump(frame.wire, node, frame.offset, link, layout))
    except EmptyInputError as exc:
        out.close()
        click.echo(f"manip-decode: {exc.message}", err=True)
        return 1
    except DecodeError as exc:
        out.close()
        click.echo(f"manip-decode: malformed {link} input: {exc}", err=True)
        return 1
    finally:
        src.close()
    out.close()
    if bad:
        click.echo(f"manip-decode: {bad} {link} frame(s) did not decode (shown in place)", err=True)
    if failed:
        click.echo(
            f"manip-decode: {failed} packet(s) are malformed (their decode errors are shown in place)",
            err=True,
        )
    if _nothing_matched(filters, out):
        return 1
    return 1 if failed or bad else 0


_STREAMS: Final = frozenset({"tcp", "chaosd"})
"""Framings whose input is a stream of frames, whose answers are paired with their requests."""


def _describe_paired(
    packet: Packet,
    direction: ReadAs,
    request: int | str | None,
    pairing: StreamPairing | None,
    *,
    header: bool,
) -> TreeNode:
    """The packet's tree; in a stream, its side and its request's layout from the pairing
    (``--direction`` and ``--request-opcode`` win over it)."""
    if pairing is None:
        return describe_packet(packet, direction=direction, request=request, header=header)
    placed = pairing.place(packet)
    side = placed.side if direction == "auto" else direction
    node = describe_packet(packet, direction=side, request=placed.request_opcode, header=header)
    if placed.request_opcode is not None:
        op = SPEC.requests.get(placed.request_opcode)
        name = f"{op.name} {octal(placed.request_opcode)}" if op else octal(placed.request_opcode)
        how = "by position" if placed.side != "auto" else "by the number it carries"
        node.add("answers", f"request #{placed.request_no} ({name}), paired {how}")
    return node


def _dump(
    wire: bytes,
    node: TreeNode,
    start: int,
    framing: str,
    layout: FrameLayout,
    origin: str = "the start of the input",
) -> Callable[[], str]:
    """The hexdump of one frame, made only if the format asks for it."""
    return lambda: render_hexdump(
        wire,
        node,
        start=start,
        base=layout.prefix,
        msb_first=layout.msb_first,
        trailer=layout.trailer,
        note=f"{framing}: {layout.note}",
        origin=origin,
    )


def _decode_body(body: tuple[str, str], source: str | None, binary: bool | None, fmt: str) -> int:
    side, op = body
    if side not in ("request", "response"):
        raise click.BadParameter(f"{side!r}: use request or response", param_hint="--body")
    key = _opcode_key(op)
    if not (side == "response" and key in _SERVER_NAMES):
        try:
            request_op(key)
        except KeyError as exc:
            raise click.BadParameter(str(exc.args[0]), param_hint="--body") from None
    src = open_source(source)
    try:
        data = b"".join(byte_blocks(src, binary))
    finally:
        src.close()
    node = describe_body("request" if side == "request" else "response", key, data)
    out = _Out(fmt)
    out.node(
        node,
        hexdump=lambda: render_hexdump(data, node, base=-1, note="a bare body: packet data, natural order"),
    )
    out.close()
    return 1 if any(_failed(c) for c in [node, *node.children]) else 0


def _decode_cougar(source: str | None, cougar: str, fmt: str) -> int:
    if source not in (None, "-") and not os.path.exists(source) and not _WORDS.match(source):
        raise SourceError(f"no such file: {source} (and it is not a list of hex words either)", usage=True)
    text = read_text(source)
    stream = WordStream("command" if cougar == "command" else "response")
    items = stream.feed(_parse_words(text))
    node = describe_words(items, cougar)
    if stream.pending:
        node.add(
            "incomplete",
            f"{len(stream.pending)} word(s) waiting for the rest of a message",
            list(stream.pending),
        )
    out = _Out("json" if fmt == "json" else "tree")
    out.node(node)
    out.close()
    bad = sum(c.label in ("out of sync", "malformed") for c in node.children)
    if bad:
        click.echo(
            f"manip-decode: {bad} Cougar message(s) out of sync or malformed (shown in place)", err=True
        )
    elif stream.pending:
        click.echo(
            f"manip-decode: the stream ends inside a message ({len(stream.pending)} word(s) of it)", err=True
        )
    return 1 if bad or stream.pending else 0


# ---------------------------------------------------------------------------------------- captures


def _decode_capture(
    mcap: str | None, pcap: str | None, ports: tuple[int, ...], fmt: str, filters: Filters
) -> int:
    """Every packet of a manip capture or a pcap: its listing line, then its tree; 1 if any fails."""
    from manip.captures import CapturedPacket, CaptureError  # noqa: PLC0415
    from manip.captures.listing import packet_line, when  # noqa: PLC0415

    path = require_file(mcap if mcap is not None else pcap or "")
    items: Iterable[CapturedPacket]
    framings: dict[int, str] = {}
    if mcap is not None:
        items = _mcap_items(path, framings)
        origin = "the start of the frame (as recorded)"
    else:
        from manip.captures.pcap import iter_pcap_packets  # noqa: PLC0415

        items = iter_pcap_packets(path, ports=ports)
        origin = "the start of the UDP payload"
    out = _Out(fmt)
    failed = 0
    start: int | None = None
    try:
        for item in items:
            if start is None:
                start = item.time_ns
                out.text(f"{os.path.basename(path)}: first packet at {when(start)}; times below are from it")
            if not filters.wants_conn(item.conn):
                continue
            direction = item.direction
            if item.packet is None:
                failed += 1
                if not filters.ops:
                    node = TreeNode(f"packet {item.seq}", packet_line(item, start))
                    err = item.annotation.decode_error or {}
                    node.add("decode error", str(err.get("message", "?")), err)
                    out.node(node, line=packet_line(item, start) if fmt != "json" else None)
                continue
            if not filters.wants(item.packet.opcode, op=item.op, direction=direction):
                continue
            side: ReadAs = "request" if direction == "c2s" else "response"
            request = item.op if direction == "s2c" and item.op is not None else None
            if request is not None:
                try:
                    request_op(request)
                except KeyError:  # the initial RESPONSE (to the RFC), or a reply to an unknown opcode
                    request = None
            node = describe_packet(item.packet, direction=side, request=request)
            failed += _failed(node)
            line = packet_line(item, start)
            if fmt == "json":
                node.label = f"packet {item.seq}"
                node.text = line
                out.node(node)
                continue
            framing = framings.get(item.link, "chudp")
            layout = LAYOUTS.get(framing, LAYOUTS["raw"])
            out.node(node, line=line, hexdump=_dump(item.frame, node, 0, framing, layout, origin))
    except CaptureError as exc:
        out.close()
        click.echo(f"manip-decode: {exc}", err=True)
        return 1
    out.close()
    return _capture_status(path, start is not None, failed, filters, out)


def _capture_status(path: str, any_packet: bool, failed: int, filters: Filters, out: _Out) -> int:
    """The exit status of a capture's decoding, said on stderr when it is not 0."""
    if not any_packet:
        click.echo(f"manip-decode: {path} holds no packets", err=True)
        return 1
    if _nothing_matched(filters, out):
        return 1
    if failed:
        click.echo(
            f"manip-decode: {failed} packet(s) of {path} did not decode or are malformed (shown in place); "
            "a recording of negative tests holds such packets on purpose",
            err=True,
        )
        return 1
    return 0


def _nothing_matched(filters: Filters, out: _Out) -> bool:
    """Like grep: a filter that selects nothing is said, and is exit status 1."""
    if (filters.ops or filters.conns) and not out.count:
        click.echo("manip-decode: no packet matches --filter", err=True)
        return True
    return False


def _mcap_items(path: str, framings: dict[int, str]) -> Iterator[Any]:
    """The packets of a manip capture; ``framings`` learns each link's framing as its channel is read."""
    from manip.captures import iter_packets  # noqa: PLC0415
    from manip.captures.reader import Capture  # noqa: PLC0415

    capture = Capture(path)
    for item in iter_packets(path, capture=capture):
        if item.link not in framings and item.link in capture.links:
            framings[item.link] = capture.links[item.link].framing
        yield item
