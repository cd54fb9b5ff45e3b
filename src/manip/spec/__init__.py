"""The protocols as data: clauses, opcode tables, layouts, error codes, Cougar commands and errata.

``SPEC`` is the loaded, cross-checked specification; everything else in manip is driven from it.
"""

from manip.spec.constants import RequestName
from manip.spec.loader import Spec, SpecError, UnknownClauseError, load_spec
from manip.spec.model import (
    AsyncCode,
    ChaosOpcode,
    Clause,
    CougarField,
    CougarMessage,
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
from manip.spec.notation import octal, octal_words

SPEC: Spec = load_spec()

__all__ = [
    "SPEC",
    "AsyncCode",
    "ChaosOpcode",
    "Clause",
    "CougarField",
    "CougarMessage",
    "Erratum",
    "ErrorCode",
    "Field",
    "FieldType",
    "Layout",
    "Origin",
    "RequestName",
    "RequestOpcode",
    "ResponseShape",
    "ServerOpcode",
    "Severity",
    "Spec",
    "SpecError",
    "UnknownClauseError",
    "load_spec",
    "octal",
    "octal_words",
]
