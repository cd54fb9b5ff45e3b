"""Multi-packet replies: describe-self's text split across packets where a reader is most likely to go
wrong (inside a keyword, a string, a number), and many packets at once."""

from __future__ import annotations

import itertools
from collections.abc import Callable
from typing import Final

from manip.codecs.lispm_text import decode_lispm, encode_lispm
from manip.conformance.cases.client._support import close, connect, request
from manip.conformance.client.runner import ClientContext, Play, client_context
from manip.conformance.client.server import ServerSide
from manip.conformance.judge.violation import showing
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext

DESCRIPTION: Final = (
    '((:brand-name "Unimation Puma 600")\n'
    ' (:unique-name "PUMA-1985")\n'
    " (:degrees-of-freedom 6)\n"
    " (:software-version 1234.)\n"
    " (:protocol-version 1)\n"
    " (:operations 200 201 202 203 204 205 206 207 210 211 212 213 214 215 216 217 220 221))"
)
"""The judge's description; its newlines go out as the Lisp Machine's Return (0215)."""


def _inside(token: str) -> Callable[[ClientContext, bytes], list[int]]:
    """A split point strictly inside ``token`` of the text, chosen by the seed."""

    def choose(ctx: ClientContext, raw: bytes) -> list[int]:
        at = raw.index(token.encode())
        return [at + ctx.random.randint(1, len(token) - 1)]

    return choose


SPLITS: Final = (
    ("mid-token", ":degrees-of-freedom", "inside a keyword"),
    ("mid-string", '"Unimation Puma 600"', "inside a string"),
    ("mid-number", "1234.", "inside a number"),
)


def chunks_at(raw: bytes, cuts: list[int]) -> list[bytes]:
    edges = [0, *sorted(set(cuts)), len(raw)]
    return [raw[a:b] for a, b in itertools.pairwise(edges) if b > a]


async def play_description(ctx: ClientContext, chunks: list[bytes], **kw: object) -> Play:
    async def script(side: ServerSide) -> None:
        req = await side.next_request()
        if req is not None:
            await side.text_reply(req, chunks)
            await side.serve_plainly()

    return await ctx.play([connect(0), request(1, "describe-self"), close(2)], script, **kw)  # type: ignore[arg-type]


def expect_text(ctx: ClientContext, play: Play, raw: bytes, *, clause: str = "client.multi-packet") -> None:
    answer = play.answer(1)
    ctx.expect(
        answer is not None and answer.type == "reply",
        clause=clause,
        expected="a reply to describe-self",
        seen=str(answer) if answer is not None else play.describe(),
    )
    assert answer is not None
    values = answer.get("values") or {}
    raw_seen = str((answer.get("raw") or {}).get("text", "")).upper()
    ctx.expect(
        values.get("text") == decode_lispm(raw),
        clause=clause,
        expected=f"the whole text, {len(raw)} bytes: {decode_lispm(raw)!r}",
        seen=showing(raw, repr(values.get("text"))),
    )
    ctx.expect(
        raw_seen == raw.hex().upper(),
        clause=clause,
        expected=f"raw text {raw.hex().upper()}",
        seen=str(raw_seen),
    )


@case.each(SPLITS)
def _split_case(row: tuple[str, str, str]) -> None:
    name, token, where = row

    async def split(base: CaseContext) -> None:
        ctx = client_context(base)
        raw = encode_lispm(DESCRIPTION)
        cuts = _inside(token)(ctx, raw)
        await _check(ctx, raw, cuts)

    case(
        f"client.describe.split-{name}",
        clauses=["client.multi-packet"],
        summary=f"Describe self split across packets {where} is read as one text",
    )(split)


async def _check(ctx: ClientContext, raw: bytes, cuts: list[int]) -> None:
    play = await play_description(ctx, chunks_at(raw, cuts))
    expect_text(ctx, play, raw)


@case("client.describe.many-packets", clauses=["client.multi-packet"], technique="property")
async def many_packets(base: CaseContext) -> None:
    """Describe self in 8 to 24 packets cut at random points (one byte each, some) is read as one text."""
    ctx = client_context(base)
    raw = encode_lispm(DESCRIPTION)
    cuts = ctx.random.sample(range(1, len(raw)), ctx.random.randint(7, 23))
    await _check(ctx, raw, cuts)
