"""Request and response code registries, handler types and data extractors."""

from __future__ import annotations

from typing import Any

import pytest

from manip.reference_client import (
    DEFAULT_REGISTRY,
    Registry,
    RequestCode,
    ResponseType,
    default_registry,
    define_data_extractor,
    define_request_code,
    define_response_code,
    define_response_handler,
    define_response_handler_type,
)
from manip.reference_client.extractors import extract_alist, extract_segment, extract_transform
from manip.spec import SPEC


def test_every_spec_opcode_is_a_request_code() -> None:
    registry = default_registry()
    for op in SPEC.requests.values():
        code = registry.request_code(op.name)
        assert code.opcode == op.opcode and code.spec is op
        assert code.manipulator_type == ("puma" if op.extension else None)
        assert registry.request_code(op.opcode, "puma") is code


def test_default_extractors_follow_the_reply_shape() -> None:
    registry = default_registry()

    def extractor(name: str) -> Any:
        return registry.resolve_extractor(registry.request_code(name).default_extractor)

    assert extractor("here") is extract_transform
    assert extractor("solve-backwards") is extract_transform
    assert extractor("move") is extract_segment
    assert extractor("describe-self") is extract_alist
    assert registry.request_code("describe-self").response_type is ResponseType.MULTI
    assert registry.request_code("here").response_type is ResponseType.SINGLE


def test_generic_response_codes() -> None:
    registry = default_registry()
    names = {c.name: c.code for c in registry.response_codes()}
    assert names == {
        "normal-response": 0,
        "fatal-error": 1,
        "non-fatal-error": 2,
        "asynchronous-response": 3,
        "asynchronous-error": 4,
        "asynchronous-warning": 5,
    }
    assert registry.response_code(2).name == "non-fatal-error"
    assert registry.handler_types() == ("generic", "chaos-manipulator", "notify-trivial-errors")


def test_names_are_case_insensitive_and_underscores_are_dashes() -> None:
    registry = default_registry()
    assert registry.request_code("SET_SPEED") is registry.request_code("set-speed")


def test_opcode_lookup_prefers_the_manipulator_type() -> None:
    registry = Registry()
    generic = registry.define_request_code("frob", 0o250)
    cougar = registry.define_request_code("twiddle", 0o250, "cougar")
    assert registry.request_code(0o250) is generic
    assert registry.request_code(0o250, "cougar") is cougar
    assert registry.request_code(0o250, "puma") is generic
    with pytest.raises(KeyError, match="0251"):
        registry.request_code(0o251)
    with pytest.raises(KeyError, match="nothing"):
        registry.request_code("nothing")


def test_define_checks_its_arguments() -> None:
    registry = default_registry()
    with pytest.raises(ValueError):
        registry.define_request_code("big", 0x100)
    with pytest.raises(KeyError, match="no data extractor"):
        registry.define_request_code("odd", 0o222, None, "no-such-extractor")
    with pytest.raises(KeyError):
        registry.define_response_handler("no-such-code", "generic", lambda ctx: None)
    with pytest.raises(ValueError):
        registry.define_response_handler("normal-response", "no-such-type", lambda ctx: None)


def test_copies_are_independent() -> None:
    base = default_registry()
    copy = base.copy()
    copy.define_request_code("extra", 0o222)
    copy.define_response_handler_type("mine")
    with pytest.raises(KeyError):
        base.request_code("extra")
    assert "mine" not in base.handler_types()


def test_module_level_defines_change_the_default_registry() -> None:
    def halve(request: Any, payloads: Any) -> int:
        return len(b"".join(payloads)) // 2

    try:
        define_data_extractor("half-length", halve)
        code = define_request_code(
            "test-probe", 0o237, "test-arm", "half-length", response_type=ResponseType.MULTI
        )
        assert isinstance(code, RequestCode) and DEFAULT_REGISTRY.request_code(0o237, "test-arm") is code
        assert define_response_code("test-response", 0o77).code == 0o77
        assert define_response_handler_type("test-type") == "test-type"
        handler = define_response_handler("test-response", "test-type", lambda ctx: None)
        assert DEFAULT_REGISTRY.find_handler(0o77, ("generic", "test-type")) == (1, handler)
    finally:
        DEFAULT_REGISTRY.__dict__.update(default_registry().__dict__)
