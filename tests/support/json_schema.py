"""A small JSON Schema checker for the keywords the project's schemas use, shared by every test that
checks a document against one: the conformance report (``report.schema.json``), the capture view and
field schemas, and Foxglove's published ``FrameTransform`` schema.

Keywords: ``$ref`` (to ``#/$defs/...`` of ``root``), ``type`` (one or a list), ``const``, ``enum``,
``minimum`` and ``maximum`` (numbers only), ``pattern``, ``required``, ``properties``,
``additionalProperties: false`` (unless ``patternProperties`` is given), ``items``, ``minItems``,
``maxItems``.  A failure is an ``AssertionError`` naming the path of the value."""

from __future__ import annotations

import re
from typing import Any

_TYPES: dict[str, type | tuple[type, ...]] = {
    "object": dict,
    "array": list,
    "string": str,
    "boolean": bool,
    "integer": int,
    "number": (int, float),
    "null": type(None),
}


def _is(instance: Any, kind: str) -> bool:
    if kind in ("integer", "number") and isinstance(instance, bool):
        return False
    return isinstance(instance, _TYPES[kind])


def validate(
    instance: Any, schema: dict[str, Any], root: dict[str, Any] | None = None, path: str = "$"
) -> None:
    """Assert that ``instance`` matches ``schema``; ``root`` is the document ``$ref`` points into (the
    schema itself when not given)."""
    root = schema if root is None else root
    if "$ref" in schema:
        name = schema["$ref"].rsplit("/", 1)[-1]
        validate(instance, root["$defs"][name], root, path)
        return
    kinds = schema.get("type")
    if kinds is not None:
        names = kinds if isinstance(kinds, list) else [kinds]
        assert any(_is(instance, k) for k in names), f"{path}: {instance!r} is not {kinds}"
    if "const" in schema:
        assert instance == schema["const"], path
    if "enum" in schema:
        assert instance in schema["enum"], f"{path}: {instance!r} not in {schema['enum']}"
    if isinstance(instance, int | float) and not isinstance(instance, bool):
        if "minimum" in schema:
            assert instance >= schema["minimum"], f"{path}: {instance} < {schema['minimum']}"
        if "maximum" in schema:
            assert instance <= schema["maximum"], f"{path}: {instance} > {schema['maximum']}"
    if "pattern" in schema:
        assert re.search(schema["pattern"], instance), f"{path}: {instance!r} !~ {schema['pattern']}"
    if isinstance(instance, dict):
        _validate_object(instance, schema, root, path)
    if isinstance(instance, list):
        assert len(instance) >= schema.get("minItems", 0), path
        assert len(instance) <= schema.get("maxItems", len(instance)), path
        for i, item in enumerate(instance):
            validate(item, schema.get("items", {}), root, f"{path}[{i}]")


def _validate_object(
    instance: dict[str, Any], schema: dict[str, Any], root: dict[str, Any], path: str
) -> None:
    for key in schema.get("required", []):
        assert key in instance, f"{path}: missing {key}"
    props = schema.get("properties", {})
    if schema.get("additionalProperties") is False and "patternProperties" not in schema:
        extra = set(instance) - set(props)
        assert not extra, f"{path}: unexpected {extra}"
    for key, value in instance.items():
        if key in props:
            validate(value, props[key], root, f"{path}.{key}")
