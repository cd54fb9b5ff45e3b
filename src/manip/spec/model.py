"""Typed view of the spec data.  Plain frozen dataclasses: the TOML files are the source of truth."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final, Literal, get_args

from manip.spec.constants import RequestName

Level = Literal["MUST", "SHOULD", "MAY", "INFO"]
Party = Literal["server", "client", "both", "cougar", "puma", "link"]
Origin = Literal["guide", "manip", "chaosnet"]
"""Whose statement a clause is: the 1985 guide's, manip's decision where the guide is silent or
ambiguous (an erratum says why), or the Chaosnet documents' (AIM 628, CHUDP, the chaosd socket)."""
Hazard = Literal["read-only", "config", "motion", "power"]
LEVELS: Final[tuple[Level, ...]] = get_args(Level)
"""The clause levels, strongest first: the one order of levels every report and judge uses."""
HAZARDS: Final[tuple[Hazard, ...]] = get_args(Hazard)
"""The hazard classes of a request, least dangerous first: the one order of hazards."""
ResponseForm = Literal["done", "data", "segment", "multi"]
Element = Literal["float", "word", "int16", "small", "counted", "text"]

Freedom = Literal[
    "error.where",
    "error.code",
    "error.message",
    "error.args-layout",
    "async.layout",
    "data.length-unit",
    "answer.length-unit",
    "answer.configuration-bits",
    "request.extension-served",
    "error.abort-scope",
]
"""A part of an answer that is the implementation's choice where a clause or erratum says so
(``freedom = [...]`` in the spec data): two conforming servers may differ there.  ``manip-conform diff``
names the clause or erratum declaring the freedom for each such difference."""
FREEDOMS: tuple[str, ...] = Freedom.__args__  # type: ignore[attr-defined]

ELEMENT_BYTES: dict[str, int] = {"float": 4, "word": 2, "int16": 2, "small": 2}
"""Bytes per element of fixed-size element kinds (``small`` may also arrive as a single byte)."""


@dataclass(frozen=True, slots=True)
class Clause:
    id: str
    level: Level
    party: Party
    section: str
    text: str
    origin: Origin
    """``guide``, ``manip`` or ``chaosnet`` (:data:`Origin`); every clause states it."""
    errata: str | None = None
    retired: bool = False
    replaced_by: tuple[str, ...] = ()
    """For a retired clause: the clause(s) that say it now (a renamed clause keeps its old id here)."""
    judged_from: Literal["live", "recording"] = "live"
    """``recording`` for a client rule about what a client chooses to send of its own accord (which guard
    number, when to send set-weight): a request op tells a harness exactly what to send, so the rule is
    judged from a recording of the client at work (``manip-conform verify --judge client``) and, live,
    through the harness contract's choice operations (docs/client-harness.md section 4.4), by the same
    rule code."""
    freedom: tuple[Freedom, ...] = ()
    """The parts of an answer this clause leaves to the implementation (:data:`Freedom`)."""


@dataclass(frozen=True, slots=True)
class Erratum:
    id: str
    clauses: tuple[str, ...]
    question: str
    decision: str
    reason: str | None = None
    parameter: str | None = None
    freedom: tuple[Freedom, ...] = ()
    """The parts of an answer this decision leaves to the implementation (:data:`Freedom`)."""


@dataclass(frozen=True, slots=True)
class FieldType:
    name: str
    element: Element
    count: int | None  # None: variable length (counted words, text)

    @property
    def fixed_size(self) -> int | None:
        """Size in bytes when fixed (``small`` counts as its word form)."""
        if self.count is None:
            return None
        return ELEMENT_BYTES[self.element] * self.count


@dataclass(frozen=True, slots=True)
class Field:
    name: str
    type: FieldType


@dataclass(frozen=True, slots=True)
class Layout:
    fields: tuple[Field, ...]

    @property
    def fixed_size(self) -> int | None:
        sizes = [f.type.fixed_size for f in self.fields]
        if any(s is None for s in sizes):
            return None
        return sum(s for s in sizes if s is not None)


@dataclass(frozen=True, slots=True)
class ResponseShape:
    form: ResponseForm
    """done, data, segment or multi (``response = { form = ... }`` in manip.toml)."""
    data: Layout


@dataclass(frozen=True, slots=True)
class RequestOpcode:
    opcode: int
    name: RequestName
    title: str
    hazard: Hazard
    request: Layout
    response: ResponseShape
    section: str
    summary: str
    extension: bool = False
    cougar: str | None = None
    answer_within: float | None = None
    """Seconds a server may take to answer because the answer waits for the arm (None: no such wait,
    the answer comes as soon as the request is processed)."""
    reply_clauses: tuple[str, ...] = ()
    """The clauses of this opcode's own reply shape (``here.transform``...), as the spec data states
    them: what a well-formed exchange of it exercises beyond the common reply clauses."""

    def answer_time(self, reply_timeout: float, scale: float = 1.0) -> float:
        """How long to wait for the answer: ``reply_timeout``, or ``answer_within`` (times ``scale``)
        when the answer waits for the arm and that is longer."""
        if self.answer_within is None:
            return reply_timeout
        return max(reply_timeout, self.answer_within * scale)


@dataclass(frozen=True, slots=True)
class ServerOpcode:
    opcode: int
    name: str
    title: str
    generic_code: int
    body: str
    generic_name: str | None = None
    answers: bool = False
    """It answers a request (a reply, or the fatal error that ends the connection)."""
    asynchronous: bool = False
    """It is sent unasked, between replies."""


@dataclass(frozen=True, slots=True)
class Severity:
    letter: str
    name: str
    meaning: str
    fatal: bool
    bug: bool
    server_opcodes: tuple[int, ...]


@dataclass(frozen=True, slots=True)
class ErrorCode:
    code: str
    meaning: str
    origin: str
    args: str | None = None
    severities: tuple[str, ...] = ()
    """The severities the reference server sends this code with (a test holds the table to what the
    server can emit)."""


@dataclass(frozen=True, slots=True)
class AsyncCode:
    code: int
    name: str
    word2: str
    word3: str
    notification_bit: int


@dataclass(frozen=True, slots=True)
class ChaosOpcode:
    name: str
    value: int
    controlled: bool
    meaning: str


@dataclass(frozen=True, slots=True)
class CougarField:
    name: str
    element: Element
    count: int | None  # None only for counted words

    @property
    def words(self) -> int | None:
        if self.count is None:
            return None
        per = 2 if self.element == "float" else 1
        return per * self.count


@dataclass(frozen=True, slots=True)
class CougarMessage:
    """A Puma->Cougar command or a Cougar->Puma response of Table 1."""

    code: int
    name: str
    data: tuple[CougarField, ...]
    remarks: str
    label: str | None = None
    response: str | None = None

    @property
    def data_words(self) -> int | None:
        """Number of data words after the code word; None when the message carries its own count."""
        total = 0
        for f in self.data:
            if f.words is None:
                return None
            total += f.words
        return total
