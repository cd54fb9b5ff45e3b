"""``manip-decode``: show what a packet (or a Cougar word stream) means, field by field.

Exit status: 0 decoded; 1 the input is malformed (the message says what, where and which clause);
2 usage error.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import click

from manip.captures import CaptureError, iter_packets
from manip.captures.listing import packet_line
from manip.codecs.chaos import encode_raw
from manip.codecs.cougar import WordStream
from manip.codecs.errors import CodecError
from manip.codecs.framing import FRAMINGS
from manip.codecs.messages import request_op
from manip.decode.describe import Node, ReadAs, describe_packet, describe_words
from manip.decode.render import render_hexdump, render_json, render_tree

_HEX_TEXT = re.compile(rb"^[\s0-9a-fA-Fx:,]*$")


def _read_source(source: str | None, binary: bool | None) -> bytes:
    if source is None or source == "-":
        raw = sys.stdin.buffer.read()
    elif Path(source).is_file():
        raw = Path(source).read_bytes()
    else:
        raw = source.encode()
        binary = False
    if binary is None:
        binary = not _HEX_TEXT.match(raw)
    return raw if binary else _parse_hex(raw.decode("ascii", "replace"))


def _parse_hex(text: str) -> bytes:
    cleaned = re.sub(r"0x|[\s:,]", "", text)
    if len(cleaned) % 2:
        raise click.BadParameter(f"odd number of hex digits ({len(cleaned)})", param_hint="SOURCE")
    try:
        return bytes.fromhex(cleaned)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="SOURCE") from exc


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


def _request_key(value: str | None) -> int | str | None:
    if value is None:
        return None
    key: int | str = int(value, 8) if value.isdigit() else value
    try:
        request_op(key)
    except KeyError as exc:
        raise click.BadParameter(str(exc.args[0]), param_hint="--request-opcode") from None
    return key


@click.command(context_settings={"help_option_names": ["-h", "--help"], "show_default": True})
@click.argument("source", required=False)
@click.option(
    "--link", type=click.Choice(sorted(FRAMINGS)), default="chudp", help="Framing of the input bytes."
)
@click.option("--format", "fmt", type=click.Choice(["tree", "json", "hexdump"]), default="tree")
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
    "--cougar",
    type=click.Choice(["command", "response"]),
    default=None,
    help="Decode a Cougar word stream (hex words) as Puma commands or Cougar responses.",
)
@click.option("--binary/--hex", "binary", default=None, help="How to read a SOURCE file (default: guess).")
@click.option(
    "--mcap",
    type=click.Path(exists=True, dir_okay=False),
    default=None,
    help="Decode every packet of a capture (manip-capture) instead of SOURCE.",
)
@click.version_option(package_name="manip")
def main(
    source: str | None,
    link: str,
    fmt: str,
    direction: ReadAs,
    request: str | None,
    cougar: str | None,
    binary: bool | None,
    mcap: str | None,
) -> None:
    """Decode SOURCE: a hex string, a file, or - for standard input (the default)."""
    if mcap is not None:
        sys.exit(_decode_capture(mcap, fmt))
    if cougar is not None:
        text = _read_text(source)
        stream = WordStream("command" if cougar == "command" else "response")
        items = stream.feed(_parse_words(text))
        node = describe_words(items, cougar)
        if stream.pending:
            node.add(
                "incomplete",
                f"{len(stream.pending)} word(s) waiting for the rest of a message",
                list(stream.pending),
            )
        _emit([node], fmt)
        if stream.pending or any(c.label in ("out of sync", "malformed") for c in node.children):
            sys.exit(1)
        return
    data = _read_source(source, binary)
    key = _request_key(request)
    try:
        packets = FRAMINGS[link].decode(data)
    except CodecError as exc:
        click.echo(f"manip-decode: malformed {link} input: {exc}", err=True)
        sys.exit(1)
    nodes = [describe_packet(p, direction=direction, request=key) for p in packets]
    if fmt == "hexdump":
        for p, node in zip(packets, nodes, strict=True):
            click.echo(render_hexdump(encode_raw(p), node))
    else:
        _emit(nodes, fmt)
    if any(c.label == "decode error" for n in nodes for c in n.children):
        sys.exit(1)


def _decode_capture(path: str, fmt: str) -> int:
    """Every packet of a capture: its listing line, then its tree; 1 if any fails to decode."""
    failed = False
    nodes: list[Node] = []
    start: int | None = None
    try:
        for item in iter_packets(path):
            start = item.time_ns if start is None else start
            if item.packet is None:
                failed = True
                click.echo(packet_line(item, start))
                continue
            direction: ReadAs = "request" if item.direction == "c2s" else "response"
            request = item.op if item.direction == "s2c" and item.op is not None else None
            if request is not None:
                try:
                    request_op(request)
                except KeyError:  # the initial RESPONSE (to the RFC), or a reply to an unknown opcode
                    request = None
            node = describe_packet(item.packet, direction=direction, request=request)
            failed = failed or any(c.label == "decode error" for c in node.children)
            if fmt == "json":
                node.label = f"packet {item.seq}"
                node.text = packet_line(item, start)
                nodes.append(node)
            elif fmt == "hexdump":
                click.echo(packet_line(item, start))
                click.echo(render_hexdump(encode_raw(item.packet), node) + "\n")
            else:
                click.echo(packet_line(item, start))
                click.echo(render_tree(node, 1) + "\n")
    except CaptureError as exc:
        click.echo(f"manip-decode: {exc}", err=True)
        return 1
    if fmt == "json":
        click.echo(render_json(nodes))
    return 1 if failed else 0


def _read_text(source: str | None) -> str:
    if source is None or source == "-":
        return sys.stdin.read()
    if Path(source).is_file():
        return Path(source).read_text()
    return source


def _emit(nodes: list[Node], fmt: str) -> None:
    if fmt == "json":
        click.echo(render_json(nodes))
    else:
        click.echo("\n\n".join(render_tree(n) for n in nodes))
