"""The definitions every manipulator starts with, and the 1985 guide's ``define-...`` forms on them.

:func:`default_registry` builds a registry holding

* every request opcode of the spec: 0200-0221 as generic codes, the Puma extensions 0240-0261 with
  manipulator type ``"puma"``; names as in the spec (``here``, ``set-speed``, ``read-forces``, ...);
  the default extractor follows the reply shape (done, segment number, one layout value, a transform
  for ``transform`` fields, the alist for describe-self);
* the response codes of E.3: ``normal-response`` 0, ``fatal-error`` 1, ``non-fatal-error`` 2,
  ``asynchronous-error`` 4 (the 1985 guide's generic four) and ``asynchronous-response`` 3,
  ``asynchronous-warning`` 5;
* the handler types and handlers of :mod:`~manip.reference_client.handlers`;
* the extractors of :mod:`~manip.reference_client.extractors`.

:data:`DEFAULT_REGISTRY` is the one the module-level ``define_...`` functions change and a manipulator
uses unless given another.
"""

from __future__ import annotations

from typing import Any

from manip.reference_client import handlers
from manip.reference_client.extractors import BUILTIN_EXTRACTORS
from manip.reference_client.registry import Registry, ResponseCode, ResponseHandler
from manip.reference_client.request import DataExtractor, RequestCode, ResponseType
from manip.spec import SPEC, RequestOpcode

PUMA = "puma"


def _default_extractor(op: RequestOpcode) -> str:
    kind = op.response.form
    if kind in ("done", "segment"):
        return kind
    types = [f.type.name for f in op.response.data.fields]
    if kind == "multi":
        return "alist" if types == ["lisp-text"] else "text"
    if types == ["transform"]:
        return "transform"
    return "value" if len(types) == 1 else "values"


def _spec_response_name(code: int) -> str:
    for entry in SPEC.server_opcodes.values():
        if entry.generic_code == code:
            return entry.generic_name or entry.name
    raise KeyError(code)


def default_registry() -> Registry:
    """A fresh registry with the spec's codes, the built-in handlers and extractors."""
    registry = Registry()
    for name, extractor in BUILTIN_EXTRACTORS.items():
        registry.define_data_extractor(name, extractor)
    for op in sorted(SPEC.requests.values(), key=lambda o: o.opcode):
        registry.define_request_code(
            op.name,
            op.opcode,
            PUMA if op.extension else None,
            _default_extractor(op),
            response_type=ResponseType.MULTI if op.response.form == "multi" else ResponseType.SINGLE,
            spec=op,
        )
    for entry in sorted(SPEC.server_opcodes.values(), key=lambda e: e.generic_code):
        registry.define_response_code(_spec_response_name(entry.generic_code), entry.generic_code)
    for kind in (handlers.GENERIC, handlers.CHAOS_MANIPULATOR, handlers.NOTIFY_TRIVIAL_ERRORS):
        registry.define_response_handler_type(kind)
    builtin: list[tuple[str, str, ResponseHandler]] = [
        ("normal-response", handlers.GENERIC, handlers.handle_normal_response),
        ("fatal-error", handlers.GENERIC, handlers.handle_fatal_error),
        ("non-fatal-error", handlers.GENERIC, handlers.handle_non_fatal_error),
        ("asynchronous-error", handlers.GENERIC, handlers.handle_asynchronous_error),
        ("asynchronous-response", handlers.CHAOS_MANIPULATOR, handlers.handle_asynchronous_response),
        ("asynchronous-warning", handlers.CHAOS_MANIPULATOR, handlers.handle_asynchronous_warning),
        ("non-fatal-error", handlers.NOTIFY_TRIVIAL_ERRORS, handlers.notify_trivial_error),
    ]
    for code, kind, handler in builtin:
        registry.define_response_handler(code, kind, handler)
    return registry


DEFAULT_REGISTRY: Registry = default_registry()


def define_request_code(
    name: str,
    opcode: int,
    manipulator_type: str | None = None,
    default_extractor: str | DataExtractor[Any] | None = None,
    *,
    response_type: ResponseType = ResponseType.SINGLE,
) -> RequestCode:
    """``manip:define-manipulator-request-code`` on :data:`DEFAULT_REGISTRY`."""
    return DEFAULT_REGISTRY.define_request_code(
        name, opcode, manipulator_type, default_extractor, response_type=response_type
    )


def define_response_code(name: str, code: int) -> ResponseCode:
    """``manip:define-manipulator-response-code`` on :data:`DEFAULT_REGISTRY`."""
    return DEFAULT_REGISTRY.define_response_code(name, code)


def define_response_handler_type(name: str) -> str:
    """``manip:define-response-handler-type`` on :data:`DEFAULT_REGISTRY`."""
    return DEFAULT_REGISTRY.define_response_handler_type(name)


def define_response_handler(
    response_code: str | int, handler_type: str, handler: ResponseHandler
) -> ResponseHandler:
    """``manip:define-manipulator-response-handler`` on :data:`DEFAULT_REGISTRY`."""
    return DEFAULT_REGISTRY.define_response_handler(response_code, handler_type, handler)


def define_data_extractor(name: str, extractor: DataExtractor[Any]) -> DataExtractor[Any]:
    """Name an extractor on :data:`DEFAULT_REGISTRY` so request codes can refer to it."""
    return DEFAULT_REGISTRY.define_data_extractor(name, extractor)
