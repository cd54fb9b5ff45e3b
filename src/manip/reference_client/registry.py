"""Named request codes, response codes, response-handler types, handlers and data extractors (§3.2).

A :class:`Registry` holds what the 1985 guide's ``define-manipulator-request-code``,
``define-manipulator-response-code``, ``define-response-handler-type``,
``define-manipulator-response-handler`` and the data-extractor keywords defined globally.  The module
:mod:`manip.reference_client.definitions` fills one with the spec's codes and the built-in handlers and
offers the ``define_...`` functions on it; build your own (``default_registry()`` or
``DEFAULT_REGISTRY.copy()``) to extend a protocol without touching everyone else's.

Handler lookup: a response with code *c* goes to the first handler found by walking a manipulator's
handler-type list in order and asking for (*c*, type).  A handler may pass the response on to the
next type that has a handler for *c* (the 1985 guide's ``continue-manipulator-response-handler``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar

from manip.reference_client.request import (
    DataExtractor,
    RequestCode,
    ResponseType,
    normalise_name,
)
from manip.spec import RequestOpcode
from manip.spec.notation import octal

if TYPE_CHECKING:
    from manip.reference_client.matching import ResponseContext

ResponseHandler = Callable[["ResponseContext"], None]
"""Called with the context of one response packet; returns nothing (it emits events instead)."""

H = TypeVar("H", bound=ResponseHandler)

MAX_OPCODE = 0xFF


@dataclass(frozen=True, slots=True)
class ResponseCode:
    """A named response code (``define_response_code``)."""

    name: str
    code: int

    def __str__(self) -> str:
        return f"{self.name} ({self.code})"


class Registry:
    """One set of definitions.  Later definitions of a name replace earlier ones, as in Lisp."""

    def __init__(self) -> None:
        self._requests: dict[str, RequestCode] = {}
        self._responses: dict[str, ResponseCode] = {}
        self._handler_types: list[str] = []
        self._handlers: dict[tuple[int, str], ResponseHandler] = {}
        self._extractors: dict[str, DataExtractor[Any]] = {}

    def copy(self) -> Registry:
        """An independent registry with the same definitions (the entries themselves are immutable)."""
        other = Registry()
        other._requests = dict(self._requests)
        other._responses = dict(self._responses)
        other._handler_types = list(self._handler_types)
        other._handlers = dict(self._handlers)
        other._extractors = dict(self._extractors)
        return other

    # ------------------------------------------------------------------ request codes

    def define_request_code(
        self,
        name: str,
        opcode: int,
        manipulator_type: str | None = None,
        default_extractor: str | DataExtractor[Any] | None = None,
        *,
        response_type: ResponseType = ResponseType.SINGLE,
        spec: RequestOpcode | None = None,
    ) -> RequestCode:
        """Name ``opcode``.  ``manipulator_type`` None makes it generic; ``default_extractor`` is an
        extractor name (see :meth:`define_data_extractor`) or function used when a request gives none."""
        if not 0 <= opcode <= MAX_OPCODE:
            raise ValueError(f"request opcode {opcode} is not 0..0{MAX_OPCODE:o}")
        if isinstance(default_extractor, str):
            self.data_extractor(default_extractor)  # fail now on an unknown name
        code = RequestCode(
            normalise_name(name),
            opcode,
            None if manipulator_type is None else normalise_name(manipulator_type),
            default_extractor,
            response_type,
            spec,
        )
        self._requests[code.name] = code
        return code

    def request_code(self, key: str | int | RequestCode, manipulator_type: str | None = None) -> RequestCode:
        """The code named ``key``, or the code for opcode ``key``: the one defined for
        ``manipulator_type`` if there is one, else the generic one.  KeyError when there is none."""
        if isinstance(key, RequestCode):
            return key
        if isinstance(key, str):
            try:
                return self._requests[normalise_name(key)]
            except KeyError:
                raise KeyError(f"no request code named {key!r}") from None
        wanted = None if manipulator_type is None else normalise_name(manipulator_type)
        generic: RequestCode | None = None
        for code in self._requests.values():
            if code.opcode != key:
                continue
            if code.manipulator_type == wanted:
                return code
            if code.manipulator_type is None:
                generic = code
        if generic is None:
            raise KeyError(f"no request code for opcode {octal(key)}")
        return generic

    def request_codes(self) -> tuple[RequestCode, ...]:
        return tuple(self._requests.values())

    # ------------------------------------------------------------------ response codes

    def define_response_code(self, name: str, code: int) -> ResponseCode:
        if code < 0:
            raise ValueError(f"response code {code} is negative")
        entry = ResponseCode(normalise_name(name), code)
        self._responses[entry.name] = entry
        return entry

    def response_code(self, key: str | int) -> ResponseCode:
        if isinstance(key, int):
            for entry in self._responses.values():
                if entry.code == key:
                    return entry
            raise KeyError(f"no response code {key}")
        try:
            return self._responses[normalise_name(key)]
        except KeyError:
            raise KeyError(f"no response code named {key!r}") from None

    def response_codes(self) -> tuple[ResponseCode, ...]:
        return tuple(self._responses.values())

    # ------------------------------------------------------------------ handler types and handlers

    def define_response_handler_type(self, name: str) -> str:
        name = normalise_name(name)
        if name not in self._handler_types:
            self._handler_types.append(name)
        return name

    def handler_types(self) -> tuple[str, ...]:
        return tuple(self._handler_types)

    def check_handler_types(self, types: Iterable[str]) -> tuple[str, ...]:
        """``types`` normalised; ValueError names any that was never defined."""
        out = tuple(normalise_name(t) for t in types)
        unknown = [t for t in out if t not in self._handler_types]
        if unknown:
            raise ValueError(f"undefined response handler type(s) {unknown}; defined: {self._handler_types}")
        return out

    def define_response_handler(
        self, response_code: str | int, handler_type: str, handler: ResponseHandler
    ) -> ResponseHandler:
        """Make ``handler`` the handler of ``response_code`` for ``handler_type`` (both must be defined)."""
        code = self.response_code(response_code).code
        (kind,) = self.check_handler_types([handler_type])
        self._handlers[(code, kind)] = handler
        return handler

    def response_handler(self, response_code: str | int, handler_type: str) -> Callable[[H], H]:
        """Decorator form of :meth:`define_response_handler`."""

        def register(fn: H) -> H:
            self.define_response_handler(response_code, handler_type, fn)
            return fn

        return register

    def find_handler(
        self, code: int, handler_types: Sequence[str], start: int = 0
    ) -> tuple[int, ResponseHandler] | None:
        """The first handler for ``code`` among ``handler_types[start:]``, with its index in the list."""
        for index in range(start, len(handler_types)):
            handler = self._handlers.get((code, handler_types[index]))
            if handler is not None:
                return index, handler
        return None

    # ------------------------------------------------------------------ data extractors

    def define_data_extractor(self, name: str, extractor: DataExtractor[Any]) -> DataExtractor[Any]:
        self._extractors[normalise_name(name)] = extractor
        return extractor

    def data_extractor(self, name: str) -> DataExtractor[Any]:
        try:
            return self._extractors[normalise_name(name)]
        except KeyError:
            raise KeyError(f"no data extractor named {name!r}; defined: {sorted(self._extractors)}") from None

    def resolve_extractor(self, extractor: str | DataExtractor[Any] | None) -> DataExtractor[Any] | None:
        return self.data_extractor(extractor) if isinstance(extractor, str) else extractor
