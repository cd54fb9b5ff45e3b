"""The client harness contract (``docs/client-harness.md``, contract 1) as values: instructions out,
results in.

The suite writes one :class:`Instruction` per case (a ``case`` line) and reads the harness's JSON
result lines back; :func:`parse_result` checks each against the contract, so a harness that writes
something else gets a verdict naming the line, never a crash of the suite.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Final

from manip.spec import SPEC

__all__ = [
    "CHOICE_OPERATIONS",
    "CHOICE_REQUESTS",
    "CONTRACT",
    "CONTROL_OPERATIONS",
    "LINKS",
    "REQUEST_OPERATIONS",
    "RESULT_TYPES",
    "REVISION",
    "ContractError",
    "HarnessHello",
    "Instruction",
    "Op",
    "Result",
    "choice_args",
    "parse_hello",
    "parse_instruction",
    "parse_result",
    "request_args",
]

CONTRACT: Final = 1
REVISION: Final = 3
"""The contract's revision (docs/client-harness.md, "Versions"): 2 added the choice operations; 3 states
what revision 2 left unsaid (the guard word, when a guard is armed, errors of choice operations, dirty
zeros, the window when the client sends) without changing a message."""
CONTROL_OPERATIONS: Final[tuple[str, ...]] = ("connect", "close", "wait", "await-replies")
CHOICE_OPERATIONS: Final[tuple[str, ...]] = ("arm-guard", "change-load")
CHOICE_REQUESTS: Final[dict[str, int]] = {"arm-guard": 1, "change-load": 4}
"""How many request timeouts the deadline allows each choice operation (docs/client-harness.md section
4.4: the timeout applies to each request an operation sends; change-load may send set frame vector, set
weight, and clear guard requests first)."""
"""Operations that leave a choice to the client (which guard number; what to send when the load
changes), judged from what it sends (revision 2, optional)."""
REQUEST_OPERATIONS: Final[tuple[str, ...]] = tuple(op.name for op in SPEC.requests.values())
"""Every request of the spec, by name: the operations that send a request."""
LINKS: Final[tuple[str, ...]] = ("tcp", "chudp", "chaosd")
RESULT_TYPES: Final[frozenset[str]] = frozenset({"state", "reply", "error", "async", "unsupported", "done"})
STATES: Final[frozenset[str]] = frozenset({"connected", "closed", "lost", "refused"})
ERROR_ORIGINS: Final[frozenset[str]] = frozenset(
    {"non-fatal-error", "fatal-error", "asynchronous-error", "asynchronous-warning", "client"}
)
CLIENT_ERROR_KINDS: Final[frozenset[str]] = frozenset(
    {"timeout", "bad-data", "not-connected", "refused-locally", "out-of-sequence", "other"}
)


class ContractError(ValueError):
    """A line from the harness that the contract does not allow; the message says what is wrong."""


@dataclass(frozen=True)
class Op:
    """One operation of a case; ``args`` by the spec layout's field names (request operations)."""

    id: int
    op: str
    args: Mapping[str, Any] | None = None
    timeout: float | None = None
    pipeline: bool = False
    seconds: float | None = None

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"id": self.id, "op": self.op}
        if self.args is not None:
            out["args"] = dict(self.args)
        if self.timeout is not None:
            out["timeout"] = self.timeout
        if self.pipeline:
            out["pipeline"] = True
        if self.seconds is not None:
            out["seconds"] = self.seconds
        return out

    @property
    def is_request(self) -> bool:
        return self.op not in CONTROL_OPERATIONS

    def budget(self, default_timeout: float) -> float:
        """The longest this op may take: its wait, or its reply timeout."""
        if self.op == "wait":
            return self.seconds or 0.0
        timeout = self.timeout if self.timeout is not None else default_timeout
        return timeout * CHOICE_REQUESTS.get(self.op, 1)


@dataclass(frozen=True)
class Instruction:
    """A ``case`` line."""

    case: str
    seed: int
    link: str
    address: str
    contact: str
    timeout: float
    operations: tuple[Op, ...]

    def line(self) -> bytes:
        data = {
            "type": "case",
            "contract": CONTRACT,
            "revision": REVISION,
            "case": self.case,
            "seed": self.seed,
            "link": self.link,
            "target": self.address,
            "contact": self.contact,
            "timeout": self.timeout,
            "operations": [op.to_json() for op in self.operations],
        }
        return (json.dumps(data, separators=(",", ":")) + "\n").encode()

    def deadline(self, slack: float = 10.0) -> float:
        """Seconds the harness has to write ``done`` (docs/client-harness.md section 5)."""
        return sum(op.budget(self.timeout) for op in self.operations) + slack

    @property
    def needs(self) -> frozenset[str]:
        return frozenset(op.op for op in self.operations)

    @property
    def pipelined(self) -> bool:
        return any(op.pipeline for op in self.operations)


@dataclass(frozen=True)
class HarnessHello:
    name: str
    version: str
    links: frozenset[str]
    operations: frozenset[str]
    features: frozenset[str] = frozenset()

    def missing(self, instruction: Instruction, link: str) -> list[str]:
        """What the harness lacks for ``instruction`` (empty: it can run it)."""
        out = [] if link in self.links else [f"link {link}"]
        out += sorted(op for op in instruction.needs if op not in self.operations)
        if instruction.pipelined and "pipeline" not in self.features:
            out.append("feature pipeline")
        return out


@dataclass(frozen=True)
class Result:
    """One result line, checked: ``type``, ``op`` (or None) and the rest as given."""

    type: str
    op: int | None
    data: Mapping[str, Any] = field(default_factory=dict)
    line: str = ""

    def get(self, key: str, default: Any = None) -> Any:
        return self.data.get(key, default)

    def __str__(self) -> str:
        return self.line


def _load(line: str) -> dict[str, Any]:
    try:
        data = json.loads(line)
    except json.JSONDecodeError as exc:
        raise ContractError(f"not JSON ({exc.msg} at column {exc.colno})") from None
    if not isinstance(data, dict):
        raise ContractError("not a JSON object")
    return data


def _strings(data: Mapping[str, Any], key: str) -> frozenset[str]:
    value = data.get(key, [])
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise ContractError(f"hello: {key!r} must be a list of strings")
    return frozenset(value)


def parse_hello(line: str) -> HarnessHello:
    data = _load(line)
    if data.get("type") != "hello":
        raise ContractError(f"the first line must be a hello, not type {data.get('type')!r}")
    if data.get("contract") != CONTRACT:
        raise ContractError(
            f"hello: contract {data.get('contract')!r}; this suite speaks contract {CONTRACT}"
        )
    for key in ("name", "version"):
        if not isinstance(data.get(key), str):
            raise ContractError(f"hello: {key!r} must be a string")
    if "links" not in data or "operations" not in data:
        raise ContractError("hello: 'links' and 'operations' are required")
    return HarnessHello(
        str(data["name"]),
        str(data["version"]),
        _strings(data, "links"),
        _strings(data, "operations"),
        _strings(data, "features"),
    )


def _number(data: Mapping[str, Any], key: str, where: str) -> float | None:
    value = data.get(key)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ContractError(f"{where}: {key!r} must be a number")
    return float(value)


def _op(item: Any) -> Op:
    if not isinstance(item, dict):
        raise ContractError("an operation must be a JSON object")
    ident, name, args = item.get("id"), item.get("op"), item.get("args")
    if not isinstance(ident, int) or isinstance(ident, bool) or not isinstance(name, str):
        raise ContractError(f"an operation needs an integer 'id' and a string 'op': {item!r}")
    if args is not None and not isinstance(args, dict):
        raise ContractError(f"op {ident}: 'args' must be an object")
    where = f"op {ident}"
    return Op(
        ident,
        name,
        args,
        _number(item, "timeout", where),
        bool(item.get("pipeline", False)),
        _number(item, "seconds", where),
    )


def request_args(name: str, args: Mapping[str, Any] | None) -> dict[str, Any]:
    """An op's ``args`` as the codec takes them (section 4.2): a JSON number of a float field is a float
    (``1`` and ``1.0`` alike), integers stay integers; KeyError for an unknown request name."""
    layout = SPEC.requests_by_name[name].request
    out = dict(args or {})
    for f in layout.fields:
        value = out.get(f.name)
        if f.type.element != "float" or value is None:
            continue
        if isinstance(value, list):
            out[f.name] = [_as_float(v) for v in value]
        else:
            out[f.name] = _as_float(value)
    return out


CHOICE_FIELDS: Final[dict[str, dict[str, tuple[int, bool]]]] = {
    "arm-guard": {"dvec": (6, True), "tol": (1, True), "stop": (0, False)},
    "change-load": {"weight": (1, True), "cg": (3, True), "offset": (3, False)},
}
"""Each choice operation's args: name -> (how many numbers, 1 a single one, 0 a boolean; required)."""


def choice_args(name: str, args: Mapping[str, Any] | None) -> dict[str, Any]:
    """A choice operation's ``args`` checked (section 4.4), numbers as floats; ContractError if not."""
    fields = CHOICE_FIELDS[name]
    out = dict(args or {})
    for key, (count, required) in fields.items():
        value = out.get(key)
        if value is None:
            if required:
                raise ContractError(f"{name}: {key!r} is required")
            continue
        if count == 0:
            if not isinstance(value, bool):
                raise ContractError(f"{name}: {key!r} must be true or false")
            continue
        items = value if count > 1 else [value]
        if not isinstance(items, list) or len(items) != count or not all(_is_number(v) for v in items):
            raise ContractError(f"{name}: {key!r} must be {count} number(s)")
        out[key] = [float(v) for v in items] if count > 1 else float(value)
    return out


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _as_float(value: Any) -> Any:
    return float(value) if isinstance(value, int) and not isinstance(value, bool) else value


def parse_instruction(line: str) -> Instruction:
    """A ``case`` line as a harness reads it (the suite's own reading, for examples and harness tests)."""
    data = _load(line)
    if data.get("type") != "case":
        raise ContractError(f"not a case instruction: type {data.get('type')!r}")
    for key in ("case", "link", "target", "contact"):
        if not isinstance(data.get(key), str):
            raise ContractError(f"case: {key!r} must be a string")
    operations = data.get("operations")
    if not isinstance(operations, list):
        raise ContractError("case: 'operations' must be a list")
    ops_ = tuple(_op(item) for item in operations)
    if len({op.id for op in ops_}) != len(ops_):
        raise ContractError("case: operation ids must be unique")
    seed, timeout = data.get("seed"), _number(data, "timeout", "case")
    if not isinstance(seed, int) or timeout is None:
        raise ContractError("case: 'seed' must be an integer and 'timeout' a number")
    return Instruction(data["case"], seed, data["link"], data["target"], data["contact"], timeout, ops_)


def _check_fields(kind: str, data: Mapping[str, Any]) -> None:
    if kind == "state":
        if data.get("state") not in STATES:
            raise ContractError(f"state {data.get('state')!r} is not one of {sorted(STATES)}")
    elif kind == "reply":
        if not isinstance(data.get("values"), dict) or not isinstance(data.get("raw"), dict):
            raise ContractError("a reply needs 'values' and 'raw' objects")
    elif kind == "error":
        origin = data.get("origin")
        if origin not in ERROR_ORIGINS:
            raise ContractError(f"error origin {origin!r} is not one of {sorted(ERROR_ORIGINS)}")
        if origin == "client" and data.get("kind") not in CLIENT_ERROR_KINDS:
            raise ContractError(
                f"client error kind {data.get('kind')!r} is not one of {sorted(CLIENT_ERROR_KINDS)}"
            )
    elif kind == "async":
        for key in ("code", "word2", "word3"):
            if not isinstance(data.get(key), int):
                raise ContractError(f"an async result needs an integer {key!r}")


def parse_result(line: str, case_id: str) -> Result:
    """One result line of case ``case_id``; :class:`ContractError` when it breaks the contract."""
    data = _load(line)
    kind = data.get("type")
    if kind not in RESULT_TYPES:
        raise ContractError(f"unknown result type {kind!r}")
    if data.get("case") != case_id:
        raise ContractError(f"result for case {data.get('case')!r} while case {case_id} runs")
    op = data.get("op")
    if op is not None and not (isinstance(op, int) and not isinstance(op, bool)):
        raise ContractError(f"'op' must be an operation id or null, not {op!r}")
    _check_fields(str(kind), data)
    return Result(str(kind), op, data, line)


def ops(*items: Op | Sequence[Op]) -> tuple[Op, ...]:
    """Flatten ops given singly or in lists (a convenience for scenarios)."""
    out: list[Op] = []
    for item in items:
        if isinstance(item, Op):
            out.append(item)
        else:
            out.extend(item)
    return tuple(out)
