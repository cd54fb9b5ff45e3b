"""Conformance cases: how one is declared, and the registry that holds them all.

A case is an ``async`` function of a :class:`~manip.conformance.suite.context.CaseContext`, declared with
:func:`case`::

    from manip.conformance.suite.case import case
    from manip.conformance.suite.context import CaseContext

    @case(
        "server.describe.terminator",                # id: target.area.name (server, cougar or client)
        clauses=["multi.terminated-by-empty"],       # clause ids of manip/spec/data/clauses.toml
        level="MUST",                                # the strongest level among the clauses (the default)
        technique="scripted",                        # scripted | negative | property | stateful
        hazard="read-only",                          # the most dangerous opcode the case may send
        deadline=5.0,                                # seconds for the whole case (scaled by --deadline-scale)
        waits=None,                                  # or: options -> seconds spent on a target's timer
        extensions=(),                               # Puma extension opcodes it uses (see below)
    )
    async def describe_terminator(ctx: CaseContext) -> None:
        # (a docstring here: its first paragraph is the case's summary)
        probe = await ctx.connect()                  # fresh Chaos connection, initial RESPONSE consumed
        answer = await probe.call("describe-self")   # every packet up to the empty terminator
        ctx.check(check_reply(answer.request, answer.packets))   # violations of the pure checkers
        ctx.expect(answer.terminated, clause="multi.terminated-by-empty",
                   expected="an empty RESPONSE ending the reply", seen=answer)

A family of cases generated from a table is declared once with :meth:`case.each <Declare.each>`: the
decorated factory is called for every row and declares that row's case, giving its summary with
``summary=`` (nothing mutates ``__doc__`` or ``__name__``)::

    @case.each(SPEC.requests.values())
    def _reply_case(op: RequestOpcode) -> None:
        async def reply_shape(ctx: CaseContext) -> None: ...
        case(f"server.reply.{op.name}", clauses=opcode_clauses(op), summary=f"{op.title}: ...")(reply_shape)

Rules a case follows:

* It reports only the clauses it declares (checked at every ``ctx.expect``/``ctx.fail``, and by
  ``tests/conformance/test_clauses.py`` over the source of every case); what the suite's own machinery
  finds on every exchange is attributed to an invariant instead (:mod:`manip.conformance.suite.invariants`).
  Its level is the strongest of its clauses' levels, and a check never overrides a clause's level.
* It says what it checks through ``ctx.expect`` / ``ctx.check`` / ``ctx.fail``: a violated clause is
  recorded and the case goes on, so that it reports every violation (a MUST fails it; a SHOULD/MAY
  makes it ``warn``, or ``fail`` under ``--strict``); ``ctx.require`` and ``ctx.fail`` stop it, for what
  the rest of the case depends on.  A clause counts as held only when one of its checks ran
  (``ctx.reached``; ``ctx.exercised`` for checks made outside ``ctx.expect``).  ``ctx.skip(reason)``
  ends it as not applicable.  Any other exception is an ``error`` of the suite, reported with its traceback.
* It never assumes state left by another case: each gets a fresh connection, which starts the
  per-connection state afresh (power, speed, segments; erratum ``server-robot``), but the arm stands
  wherever the last case left it.
* ``extensions`` names every Puma extension opcode (0240 and up, the spec's ``extension = true``: request
  notifications, reset abort, the wrist) the case sends, by spec name.  A server written from the 1985
  guide alone has none of them, so where the target does not offer one (a refusal, or absent from describe
  self's ``:operations``) the case judges the same clauses with the guide's own requests (polling Here or
  Joint angles, enable high power to clear an abort: :mod:`manip.conformance.cases._support`), or ends
  ``not-judged`` naming what would judge it; it never skips for it.  ``manip-conform cases`` and the
  reports show the mark.
* ``hazard`` is honest: with ``--target hardware`` cases above ``config`` are left out unless
  ``--allow-motion`` (property/stateful cases also read ``ctx.options.allowed_hazards`` to restrict
  what they generate).
* Cases live in modules of :mod:`manip.conformance.cases` (any module there is imported by
  :func:`load_cases`), under ``cases/server/``, ``cases/cougar/`` or ``cases/puma/`` as the id's
  target says.

Case ids are stable: never rename one that has shipped (known-failing files and reports name them).
"""

from __future__ import annotations

import importlib
import pkgutil
import re
from collections.abc import Awaitable, Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final, Literal, TypeVar, get_args

from manip.conformance.judge.violation import CarriesViolation, FailureKind, Violation
from manip.spec import SPEC
from manip.spec.model import HAZARDS, LEVELS, Hazard, Level

if TYPE_CHECKING:
    from manip.conformance.suite.context import CaseContext, RunOptions

__all__ = [
    "HAZARD_ORDER",
    "LEVEL_ORDER",
    "TECHNIQUES",
    "Case",
    "CaseError",
    "CaseFailure",
    "CaseFunction",
    "CaseSkipped",
    "Declare",
    "Target",
    "Technique",
    "UndeclaredClauseError",
    "all_cases",
    "case",
    "load_cases",
    "register",
    "strongest_level",
    "summary_of",
    "target_of",
]

Technique = Literal["scripted", "negative", "property", "stateful"]
"""How a case tests: a scripted exchange, malformed input (``negative``: the target's liveness is
checked after it), Hypothesis properties, or a Hypothesis state machine."""
TECHNIQUES: Final[tuple[str, ...]] = get_args(Technique)
Target = Literal["server", "cougar", "client", "puma"]
"""What a case tests, from the first component of its id: a manip server, a Cougar, a client, the
Puma's side of the wrist link (a server judged by the suite playing Cougar)."""

LEVEL_ORDER: Final[Mapping[str, int]] = {level: len(LEVELS) - 1 - n for n, level in enumerate(LEVELS)}
"""Strength of a level; a case's default level is the strongest among its clauses."""
HAZARD_ORDER: Final[Mapping[str, int]] = {hazard: n for n, hazard in enumerate(HAZARDS)}
"""How dangerous an opcode class is on real hardware (the spec's hazard classes)."""

CaseFunction = Callable[["CaseContext"], Awaitable[None]]
Row = TypeVar("Row")

_ID_COMPONENT = re.compile(r"^[a-z0-9][a-z0-9_-]*$")


class CaseError(Exception):
    """A case was declared wrongly (unknown clause, duplicate id, bad level...): a bug of the suite."""


class UndeclaredClauseError(CaseError):
    """A case reported a clause it does not declare (``manip.conformance.suite.invariants``)."""


class CaseFailure(CarriesViolation, Exception):  # noqa: N818 - an outcome, not an error of the suite
    """The target broke a clause: raised by ``ctx.expect``/``ctx.fail`` and the probes; ends the case as
    ``fail``.  It carries one :class:`~manip.conformance.judge.violation.Violation` (``.violation``),
    given whole or built from the same arguments (``CaseFailure("message", clause=..., ...)``)."""

    def __init__(
        self,
        message: str | Violation,
        *,
        clause: str | None = None,
        expected: str = "",
        actual: str = "",
        data: bytes = b"",
        kind: FailureKind = "wrong_value",
        invariant: str | None = None,
    ) -> None:
        violation = (
            message
            if isinstance(message, Violation)
            else Violation(
                message,
                clause,
                expected=expected,
                actual=actual,
                data=data,
                kind=kind,
                invariant=invariant,
            )
        )
        super().__init__(violation.message)
        self.violation = violation


class CaseSkipped(Exception):  # noqa: N818 - an outcome
    """The case does not apply to this target or these options (``ctx.skip``)."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


@dataclass(frozen=True)
class Case:
    """A registered case (see the module docstring for the meaning of each field)."""

    id: str
    function: CaseFunction
    clauses: tuple[str, ...]
    level: Level
    technique: Technique
    hazard: Hazard
    deadline: float
    summary: str
    module: str
    waits: Callable[[RunOptions], float] | None = None
    """Seconds the case spends waiting on a timer of the target's, added to its deadline unscaled."""
    extensions: tuple[str, ...] = ()
    """The Puma extension opcodes (spec request names) the case sends where the target offers them."""

    def deadline_for(self, options: RunOptions) -> float:
        """The case's deadline in a run with ``options``."""
        wait = 0.0 if self.waits is None else self.waits(options)
        return self.deadline * options.deadline_scale + wait

    @property
    def components(self) -> tuple[str, ...]:
        return tuple(self.id.split("."))

    @property
    def target(self) -> Target:
        """What the case tests (the first component of its id)."""
        return target_of(self.id)

    @property
    def kind(self) -> Technique:
        """Deprecated name of :attr:`technique` (the report's ``kind``)."""
        return self.technique


_REGISTRY: dict[str, Case] = {}


def target_of(case_id: str) -> Target:
    """The target a case id names: ``cougar.*``, ``client.*`` and ``puma.*`` say so; every other id is
    a server's (``server.*``, and the ``property.*``/``stateful.*`` ids that shipped before targets had
    names)."""
    first = case_id.split(".", 1)[0]
    if first == "cougar":
        return "cougar"
    if first == "client":
        return "client"
    if first == "puma":
        return "puma"
    return "server"


def strongest_level(clauses: Iterable[str]) -> Level:
    """The strongest level among clause ids (INFO when none)."""
    levels: list[Level] = [SPEC.clauses[c].level for c in clauses if c in SPEC.clauses]
    return max(levels, key=lambda lv: LEVEL_ORDER[lv], default="INFO")


def _validate(
    case_id: str, clauses: tuple[str, ...], level: str, technique: str, hazard: str, deadline: float
) -> None:
    parts = case_id.split(".")
    if len(parts) < 2 or not all(_ID_COMPONENT.match(p) for p in parts):
        raise CaseError(f"case id {case_id!r}: dot-separated lower-case components, at least two")
    if not clauses:
        raise CaseError(f"case {case_id}: names no clause")
    unknown = [c for c in clauses if c not in SPEC.clauses]
    if unknown:
        raise CaseError(f"case {case_id}: unknown clause(s) {unknown}")
    retired = [c for c in clauses if SPEC.clauses[c].retired]
    if retired:
        raise CaseError(f"case {case_id}: retired clause(s) {retired}")
    if level not in LEVEL_ORDER:
        raise CaseError(f"case {case_id}: level {level!r} is not one of {sorted(LEVEL_ORDER)}")
    strongest = strongest_level(clauses)
    if level != strongest:
        raise CaseError(
            f"case {case_id}: level {level} disagrees with its clauses, the strongest of which is "
            f"{strongest} in the spec: a check that is weaker than its clause needs a clause of its own"
        )
    if technique not in TECHNIQUES:
        raise CaseError(f"case {case_id}: technique {technique!r} is not one of {TECHNIQUES}")
    if hazard not in HAZARD_ORDER:
        raise CaseError(f"case {case_id}: hazard {hazard!r} is not one of {sorted(HAZARD_ORDER)}")
    if not deadline > 0:
        raise CaseError(f"case {case_id}: deadline must be positive")


def _validate_extensions(case_id: str, extensions: tuple[str, ...]) -> None:
    by_name = {op.name: op for op in SPEC.requests.values()}
    wrong = [name for name in extensions if name not in by_name or not by_name[name].extension]
    if wrong:
        raise CaseError(f"case {case_id}: {wrong} are not Puma extension opcodes of the spec")


class Declare:
    """The ``case`` decorator (an object, so that ``case.each`` can go with it)."""

    def __call__(
        self,
        case_id: str,
        *,
        clauses: Iterable[str],
        level: Level | None = None,
        technique: Technique = "scripted",
        hazard: Hazard = "read-only",
        deadline: float = 5.0,
        summary: str | None = None,
        waits: Callable[[RunOptions], float] | None = None,
        extensions: Iterable[str] = (),
    ) -> Callable[[CaseFunction], CaseFunction]:
        """Declare a case; the decorated function is returned unchanged (and registered).

        ``summary`` defaults to the first paragraph of the function's docstring (:func:`summary_of`)."""
        clause_ids = tuple(clauses)
        chosen: Level = level if level is not None else strongest_level(clause_ids)
        _validate(case_id, clause_ids, chosen, technique, hazard, deadline)
        extension_names = tuple(extensions)
        _validate_extensions(case_id, extension_names)

        def decorate(function: CaseFunction) -> CaseFunction:
            register(
                Case(
                    id=case_id,
                    function=function,
                    clauses=clause_ids,
                    level=chosen,
                    technique=technique,
                    hazard=hazard,
                    deadline=deadline,
                    summary=summary if summary is not None else summary_of(function.__doc__),
                    module=function.__module__,
                    waits=waits,
                    extensions=extension_names,
                )
            )
            return function

        return decorate

    @staticmethod
    def each(rows: Iterable[Row]) -> Callable[[Callable[[Row], None]], Callable[[Row], None]]:
        """Declare a family of cases from a table: the decorated factory is called once per row and
        declares that row's case (see the module docstring)."""

        def declare_all(factory: Callable[[Row], None]) -> Callable[[Row], None]:
            for row in rows:
                factory(row)
            return factory

        return declare_all


case: Final = Declare()
"""Declare a case (``@case(...)``), or a family of them from a table (``@case.each(rows)``)."""


def summary_of(doc: str | None) -> str:
    """A docstring's first paragraph on one line: whole sentences, never its first line cut where the
    source wrapped it."""
    paragraph = (doc or "").strip().split("\n\n", 1)[0]
    return " ".join(paragraph.split())


def register(item: Case) -> Case:
    """Add a case to the registry; the same id twice is a :class:`CaseError`."""
    existing = _REGISTRY.get(item.id)
    if existing is not None and existing.function is not item.function:
        raise CaseError(f"case id {item.id} registered twice ({existing.module} and {item.module})")
    _REGISTRY[item.id] = item
    return item


def load_cases(package: str = "manip.conformance.cases") -> None:
    """Import every module of ``package`` so that their ``@case`` declarations run."""
    pkg = importlib.import_module(package)
    for info in pkgutil.walk_packages(pkg.__path__, prefix=f"{package}."):
        importlib.import_module(info.name)


def all_cases(*, load: bool = True) -> list[Case]:
    """Every registered case, sorted by id (``load``: import :mod:`manip.conformance.cases` first)."""
    if load:
        load_cases()
    return sorted(_REGISTRY.values(), key=lambda c: c.id)
