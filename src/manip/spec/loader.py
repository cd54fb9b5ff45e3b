"""Load the spec data files once and check that they hang together.

The checks here are what keeps "the spec is data" honest: a clause that names a missing erratum, an
opcode defined twice, a layout naming an unknown field type or a Cougar response that does not exist
makes loading fail with a message that says which file and entry are wrong.
"""

from __future__ import annotations

import difflib
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from functools import cache
from importlib import resources
from types import MappingProxyType
from typing import Any, TypeVar, cast, get_args

from manip.spec.constants import RequestName
from manip.spec.model import (
    FREEDOMS,
    AsyncCode,
    ChaosOpcode,
    Clause,
    CougarField,
    CougarMessage,
    Element,
    Erratum,
    ErrorCode,
    Field,
    FieldType,
    Layout,
    Origin,
    RequestOpcode,
    ResponseShape,
    ServerOpcode,
    Severity,
)
from manip.spec.notation import octal

K = TypeVar("K")
V = TypeVar("V")


class SpecError(Exception):
    """The spec data files are inconsistent."""


class UnknownClauseError(KeyError):
    """A clause id the spec does not have; ``close`` are the ids that look like it (closest first).

    A :class:`KeyError`, as a missing mapping key is, but its text is the message itself."""

    def __init__(self, clause_id: str, close: Iterable[str]) -> None:
        self.clause_id = clause_id
        self.close = tuple(close)
        hint = f"; close matches: {', '.join(self.close)}" if self.close else " (docs/spec.md lists them)"
        super().__init__(f"no clause {clause_id!r} in the spec{hint}")

    def __str__(self) -> str:
        return str(self.args[0])


def close_clause_ids(clause_id: str, known: Iterable[str], limit: int = 3) -> list[str]:
    """Ids among ``known`` that look like ``clause_id`` (a typo, a word left out), the closest first."""
    return difflib.get_close_matches(clause_id, list(known), n=limit, cutoff=0.6)


@dataclass(frozen=True)
class Spec:
    """Everything manip knows about the protocols, as read from ``manip/spec/data``."""

    revision: str
    protocol_version: int
    segment_within: float
    """Seconds one queued motion segment may take at speed factor 1 (erratum ``answer-allowance``)."""
    clauses: Mapping[str, Clause]
    errata: Mapping[str, Erratum]
    field_types: Mapping[str, FieldType]
    requests: Mapping[int, RequestOpcode]
    server_opcodes: Mapping[int, ServerOpcode]
    severities: Mapping[str, Severity]
    error_codes: Mapping[str, ErrorCode]
    async_codes: Mapping[int, AsyncCode]
    chaos_opcodes: Mapping[str, ChaosOpcode]
    cougar_commands: Mapping[int, CougarMessage]
    cougar_responses: Mapping[int, CougarMessage]
    requests_by_name: Mapping[str, RequestOpcode]
    """The index of :attr:`requests` by name."""

    def request(self, key: int | RequestName) -> RequestOpcode:
        """A request opcode by number or by name (``"here"``; a misspelt name is a type error, and at
        run time a KeyError naming the key)."""
        try:
            return self.requests[key] if isinstance(key, int) else self.requests_by_name[key]
        except KeyError:
            shown = octal(key) if isinstance(key, int) else repr(key)
            raise KeyError(f"no request opcode {shown} in the spec") from None

    chaos_opcode_names: tuple[str, ...]
    """The name of each Chaos opcode 0-0377, as :meth:`chaos_opcode_name` gives it."""

    def chaos_opcode_name(self, opcode: int) -> str:
        """The Chaos opcode's name from the spec's table: RFC, OPN, ...; DAT for every 8-bit data opcode
        (0200-0277) and DWD for every 16-bit one (0300-0377); an opcode Chaos does not assign is written in
        octal (``017``).  The one name every reader of a Chaos header shows."""
        return self.chaos_opcode_names[opcode]

    def clause(self, clause_id: str) -> Clause:
        """The clause ``clause_id``; :class:`UnknownClauseError` (a KeyError) naming close matches."""
        try:
            return self.clauses[clause_id]
        except KeyError:
            raise UnknownClauseError(clause_id, close_clause_ids(clause_id, self.clauses)) from None

    def check_clause_ids(self, clause_ids: Iterable[str]) -> None:
        """Raise :class:`UnknownClauseError` for the first id the spec does not have."""
        for clause_id in clause_ids:
            self.clause(clause_id)


def _chaos_opcode_names(opcodes: Mapping[str, ChaosOpcode]) -> tuple[str, ...]:
    by_value = {op.value: op.name for op in opcodes.values()}
    dat, dwd = opcodes["DAT"], opcodes["DWD"]
    names = [by_value.get(value, octal(value)) for value in range(dat.value)]
    return (*names, *[dat.name] * (dwd.value - dat.value), *[dwd.name] * (0o400 - dwd.value))


def _read(name: str) -> dict[str, Any]:
    text = resources.files("manip.spec").joinpath("data", name).read_bytes()
    try:
        return tomllib.loads(text.decode("utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{name}: {exc}") from exc


def _unique(items: list[tuple[K, V]], what: str) -> Mapping[K, V]:
    out: dict[K, V] = {}
    for key, value in items:
        if key in out:
            raise SpecError(f"{what} {key!r} is defined twice")
        out[key] = value
    return MappingProxyType(out)


def _layout(raw: list[dict[str, Any]], types: Mapping[str, FieldType], where: str) -> Layout:
    fields = []
    for f in raw:
        if f["type"] not in types:
            raise SpecError(f"{where}: field {f['name']!r} has unknown type {f['type']!r}")
        fields.append(Field(f["name"], types[f["type"]]))
    return Layout(tuple(fields))


def _cougar(raw: list[dict[str, Any]], where: str) -> Mapping[int, CougarMessage]:
    items = []
    for m in raw:
        data = []
        for f in m.get("data", []):
            element = "counted" if f["type"] == "counted-words" else f["type"]
            if element not in ("float", "word", "int16", "counted"):
                raise SpecError(f"{where} {m['name']}: unknown field type {f['type']!r}")
            count = None if element == "counted" else int(f.get("count", 1))
            data.append(CougarField(f["name"], cast(Element, element), count))
        msg = CougarMessage(
            code=m["code"],
            name=m["name"],
            data=tuple(data),
            remarks=m["remarks"],
            label=m.get("label"),
            response=m.get("response"),
        )
        items.append((msg.code, msg))
    return _unique(items, where)


def _check_freedoms(spec: Spec) -> None:
    """Every ``freedom`` a clause or erratum declares is one of :data:`~manip.spec.model.FREEDOMS`."""
    items: list[Clause | Erratum] = [*spec.clauses.values(), *spec.errata.values()]
    for item in items:
        for part in item.freedom:
            if part not in FREEDOMS:
                raise SpecError(f"{item.id}: unknown freedom {part!r} (known: {', '.join(FREEDOMS)})")


def _check(spec: Spec) -> None:
    for c in spec.clauses.values():
        if c.errata is not None and c.errata not in spec.errata:
            raise SpecError(f"clause {c.id} names unknown erratum {c.errata!r}")
        if c.origin not in get_args(Origin):
            raise SpecError(f"clause {c.id}: origin {c.origin!r} is not one of {', '.join(get_args(Origin))}")
        if c.origin == "manip" and c.errata is None and c.section != "manip":
            raise SpecError(f"clause {c.id} is manip's decision but names no erratum saying why")
    _check_freedoms(spec)
    for e in spec.errata.values():
        for cid in e.clauses:
            if cid not in spec.clauses:
                raise SpecError(f"erratum {e.id} names unknown clause {cid!r}")
    names = {r.name: r for r in spec.cougar_responses.values()}
    for cmd in spec.cougar_commands.values():
        for resp in (cmd.response or "").split("|"):
            if resp and resp not in names:
                raise SpecError(f"Cougar command {cmd.name} names unknown response {resp!r}")
    for req in spec.requests.values():
        if not 0o200 <= req.opcode <= 0o277:
            raise SpecError(f"request {req.name} opcode {octal(req.opcode)} outside 0200-0277")
        if req.cougar and req.cougar not in {c.name for c in spec.cougar_commands.values()}:
            raise SpecError(f"request {req.name} names unknown Cougar command {req.cougar!r}")
        if req.response.form in ("done", "segment") and req.response.data.fields:
            raise SpecError(f"request {req.name}: a {req.response.form} response carries no layout")
    _check_clause_links(spec)


def _check_clause_links(spec: Spec) -> None:
    """What the data states about clauses resolves: each opcode's reply clauses, each renamed clause's
    successors."""
    for req in spec.requests.values():
        for cid in req.reply_clauses:
            if cid not in spec.clauses or spec.clauses[cid].retired:
                raise SpecError(f"request {req.name} names unknown or retired reply clause {cid!r}")
    for c in spec.clauses.values():
        if c.judged_from not in ("live", "recording") or (
            c.judged_from == "recording" and c.party != "client"
        ):
            raise SpecError(
                f"clause {c.id}: judged_from {c.judged_from!r} (only client clauses may be 'recording')"
            )
        for cid in c.replaced_by:
            if not c.retired or cid not in spec.clauses or spec.clauses[cid].retired:
                raise SpecError(f"clause {c.id}: replaced_by {cid!r} needs a retired clause and a live one")


@cache
def load_spec() -> Spec:
    """Read and cross-check the spec data (cached: the files are read once per process)."""
    chaos = _read("chaos.toml")
    manip = _read("manip.toml")
    cougar = _read("cougar.toml")
    clauses = _read("clauses.toml")
    errata = _read("errata.toml")

    chaos_opcodes = _unique([(o["name"], ChaosOpcode(**o)) for o in chaos["chaos_opcode"]], "Chaos opcode")
    types = _unique(
        [(t["name"], FieldType(t["name"], t["element"], t.get("count"))) for t in manip["field_type"]],
        "field type",
    )
    requests = []
    for r in manip["request"]:
        where = f"request {r['name']}"
        shape = ResponseShape(r["response"]["form"], _layout(r["response"].get("data", []), types, where))
        op = RequestOpcode(
            opcode=r["opcode"],
            name=r["name"],
            title=r["title"],
            hazard=r["hazard"],
            request=_layout(r["request"], types, where),
            response=shape,
            section=r["section"],
            summary=r["summary"],
            extension=r.get("extension", False),
            cougar=r.get("cougar"),
            answer_within=r.get("answer_within"),
            reply_clauses=tuple(r.get("reply_clauses", ())),
        )
        requests.append((op.opcode, op))

    spec = Spec(
        revision=manip["revision"],
        protocol_version=manip["protocol_version"],
        segment_within=float(manip["segment_within"]),
        clauses=_unique(
            [
                (
                    c["id"],
                    Clause(
                        **{
                            **c,
                            "replaced_by": tuple(c.get("replaced_by", ())),
                            "freedom": tuple(c.get("freedom", ())),
                        }
                    ),
                )
                for c in clauses["clause"]
            ],
            "clause",
        ),
        errata=_unique(
            [
                (
                    e["id"],
                    Erratum(**{**e, "clauses": tuple(e["clauses"]), "freedom": tuple(e.get("freedom", ()))}),
                )
                for e in errata["erratum"]
            ],
            "erratum",
        ),
        field_types=types,
        requests=_unique(requests, "request opcode"),
        server_opcodes=_unique(
            [(s["opcode"], ServerOpcode(**s)) for s in manip["server_opcode"]], "server opcode"
        ),
        severities=_unique(
            [
                (s["letter"], Severity(**{**s, "server_opcodes": tuple(s["server_opcodes"])}))
                for s in manip["severity"]
            ],
            "severity",
        ),
        error_codes=_unique(
            [
                (e["code"], ErrorCode(**{**e, "severities": tuple(e.get("severities", ()))}))
                for e in manip["error_code"]
            ],
            "error code",
        ),
        async_codes=_unique([(a["code"], AsyncCode(**a)) for a in manip["async_code"]], "async code"),
        chaos_opcodes=chaos_opcodes,
        chaos_opcode_names=_chaos_opcode_names(chaos_opcodes),
        cougar_commands=_cougar(cougar["command"], "Cougar command"),
        cougar_responses=_cougar(cougar["response"], "Cougar response"),
        requests_by_name=MappingProxyType({op.name: op for _, op in requests}),
    )
    _check(spec)
    return spec
