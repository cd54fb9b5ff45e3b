"""Generate src/manip/spec/constants.py (typed IntEnums) from the spec data files.

Run after editing src/manip/spec/data/*.toml; tests/spec/test_spec.py fails while the file is stale.
"""

from __future__ import annotations

import sys
from pathlib import Path

from manip.spec import Spec, load_spec

TARGET = Path(__file__).resolve().parents[1] / "src" / "manip" / "spec" / "constants.py"

HEADER = '''"""Named constants generated from the spec data (``manip/spec/data/*.toml``).

DO NOT EDIT: regenerate with ``python tools/gen_constants.py``; a test checks this file is current.
"""

from enum import IntEnum
from typing import Final, Literal
'''


def _ident(name: str) -> str:
    return name.upper().replace("-", "_").replace("|", "_")


def _enum(name: str, doc: str, members: list[tuple[str, int]], octal: bool) -> str:
    lines = ["", "", f"class {name}(IntEnum):", f'    """{doc}"""', ""]
    for member, value in members:
        lines.append(f"    {_ident(member)} = {oct(value) if octal else value}")
    return "\n".join(lines) + "\n"


def _tables(spec: Spec) -> list[tuple[str, str, list[tuple[str, int]], bool]]:
    """(enum name, docstring, members, octal?) for every generated enum."""
    return [
        (
            "ChaosOp",
            "Chaosnet packet opcodes.",
            [(o.name, o.value) for o in spec.chaos_opcodes.values()],
            True,
        ),
        (
            "RequestOp",
            "Chaos manipulator protocol request opcodes (Puma extensions included).",
            [(r.name, r.opcode) for r in spec.requests.values()],
            True,
        ),
        (
            "ServerOp",
            "Opcodes of packets sent by the server.",
            [(s.name, s.opcode) for s in spec.server_opcodes.values()],
            True,
        ),
        (
            "AsyncCondition",
            "Condition codes of asynchronous responses (0203).",
            [(a.name, a.code) for a in spec.async_codes.values()],
            False,
        ),
        (
            "CougarCommand",
            "Puma-to-Cougar command codes (Table 1).",
            [(c.name, c.code) for c in spec.cougar_commands.values()],
            False,
        ),
        (
            "CougarResponse",
            "Cougar-to-Puma response codes (Table 1).",
            [(c.name, c.code) for c in spec.cougar_responses.values()],
            False,
        ),
    ]


def _names(name: str, doc: str, names: list[str]) -> str:
    lines = ["", "", f"{name} = Literal["]
    lines += [f'    "{n}",' for n in names]
    lines += ["]", f'"""{doc}"""']
    return "\n".join(lines) + "\n"


def _opcode_sets(spec: Spec) -> str:
    """Groups of server opcodes, from the flags of the spec data (one definition for every module)."""
    carrying = {o for s in spec.severities.values() for o in s.server_opcodes}
    groups = [
        (
            "ANSWER_OPS",
            "Server opcodes that answer a request.",
            [s for s in spec.server_opcodes.values() if s.answers],
        ),
        (
            "ASYNC_OPS",
            "Server opcodes sent unasked, between replies.",
            [s for s in spec.server_opcodes.values() if s.asynchronous],
        ),
        (
            "ERROR_STRING_OPS",
            "Server opcodes whose data is a request number and an error string (the severities' opcodes).",
            [s for s in spec.server_opcodes.values() if s.opcode in carrying],
        ),
        (
            "ERROR_REPLY_OPS",
            "Server opcodes that answer a request with an error string.",
            [s for s in spec.server_opcodes.values() if s.answers and s.opcode in carrying],
        ),
        (
            "ASYNC_ERROR_OPS",
            "Server opcodes sent unasked with an error string (which quote the last request processed).",
            [s for s in spec.server_opcodes.values() if s.asynchronous and s.opcode in carrying],
        ),
    ]
    out = ""
    for name, doc, members in groups:
        listed = "".join(f"        ServerOp.{_ident(s.name)},\n" for s in members)
        out += f"\n\n{name}: Final[frozenset[ServerOp]] = frozenset(\n    {{\n{listed}    }}\n)\n"
        out += f'"""{doc}"""\n'
    return out


def render() -> str:
    spec = load_spec()
    names = _names(
        "RequestName",
        "Every request opcode's name: a misspelt operation name is a type error.",
        [r.name for r in spec.requests.values()],
    )
    return HEADER + "".join(_enum(*table) for table in _tables(spec)) + names + _opcode_sets(spec)


def main() -> int:
    TARGET.write_text(render())
    print(f"wrote {TARGET}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
