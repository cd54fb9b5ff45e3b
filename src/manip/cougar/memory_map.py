"""A Cougar's memory map declared in a file: where the objects the conformance cases read and write live.

The 1985 guide gives DPST and EXMN addresses but no map of Cougar's memory, so every Cougar has its own
(manip's is :data:`manip.cougar.memory.MAP`, erratum ``cougar-memory-map``).  The Cougar cases that use
memory take the implementation's map as input (``manip-conform run --cougar URL --memory-map FILE``);
without one they are not judged.  The file is TOML (``docs/drv11j.md``):

.. code-block:: toml

    format = 1
    [objects]
    version = { address = 0o1000, kind = "word", count = 1 }
    k = { address = 0o1144, kind = "float", count = 6 }

Each object named is one of :data:`OBJECTS`, with its PDP-11 byte address (even) and, optionally, its
kind and count, which must then be the ones the object has (a check that the file means what the suite
means).  Every object is optional: a case that needs one the file does not name is not judged, and says
which.  :func:`memory_map_toml` writes manip's own map (or the relocated one) in this format.
"""

from __future__ import annotations

import itertools
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Final

from manip.cougar.memory import MAP, Kind, Region, region

__all__ = [
    "MAX_MAP_BYTES",
    "OBJECTS",
    "CougarMemoryMap",
    "MemoryMapError",
    "Region",
    "load_memory_map",
    "memory_map_toml",
    "own_map",
    "parse_memory_map",
]

MAX_MAP_BYTES: Final = 64 * 1024
"""A memory map file larger than this is refused unread."""
FORMAT: Final = 1
ADDRESS_SPACE: Final = 0o200000
"""Bytes a 16-bit address reaches."""
JACOBIAN_FLOATS: Final = 36
"""A Jacobian buffer holds at least J (6x6, row after row) first; what follows is the Cougar's own."""

#: The objects the Cougar cases may read or write, with the kind and count each has.  The names are
#: manip's (its regions of :data:`manip.cougar.memory.MAP`); what each holds is in ``docs/drv11j.md``.
OBJECTS: Final[Mapping[str, tuple[Kind, int]]] = {
    name: (region(name).kind, JACOBIAN_FLOATS if name.startswith("jbuf") else region(name).count)
    for name in (
        "version",
        "con",
        "object",
        "fv",
        "k",
        "b",
        "bji",
        "fc",
        "rate_difference",
        "dtheta_previous",
        "dtheta_filtered",
        "dtheta_out",
        "gauge_offsets",
        "gauge_raw",
        "gauge_filtered",
        "calmat",
        "voltmat",
        "jacob_front",
        "jbuf0",
        "jbuf1",
    )
}


class MemoryMapError(ValueError):
    """A memory map file that cannot be used; the message says where and why."""


@dataclass(frozen=True)
class CougarMemoryMap:
    """A declared map: the objects it names, and where it came from (for messages)."""

    objects: Mapping[str, Region]
    source: str = "manip's own map"

    def get(self, name: str) -> Region | None:
        return self.objects.get(name)


def parse_memory_map(text: str, source: str = "the memory map") -> CougarMemoryMap:
    """The map declared by ``text`` (TOML); :class:`MemoryMapError` saying what is wrong and where."""
    if len(text.encode("utf-8")) > MAX_MAP_BYTES:
        raise MemoryMapError(f"{source}: larger than {MAX_MAP_BYTES} bytes")
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise MemoryMapError(f"{source}: not TOML: {exc}") from None
    extra = sorted(set(doc) - {"format", "objects"})
    if extra:
        raise MemoryMapError(f"{source}: unknown key(s) {extra}; a map has 'format' and 'objects'")
    if doc.get("format") != FORMAT:
        raise MemoryMapError(f"{source}: needs 'format = {FORMAT}' (got {doc.get('format')!r})")
    table = doc.get("objects")
    if not isinstance(table, dict) or not table:
        raise MemoryMapError(f"{source}: needs an [objects] table naming at least one object")
    objects = {name: _object(source, name, entry) for name, entry in table.items()}
    _check_overlaps(source, objects)
    return CougarMemoryMap(objects, source)


def _object(source: str, name: str, entry: object) -> Region:
    where = f"{source}: objects.{name}"
    if name not in OBJECTS:
        raise MemoryMapError(f"{where}: not an object the cases use; known: {', '.join(OBJECTS)}")
    if not isinstance(entry, dict):
        raise MemoryMapError(f"{where}: needs a table {{ address = ... }}")
    extra = sorted(set(entry) - {"address", "kind", "count"})
    if extra:
        raise MemoryMapError(f"{where}: unknown key(s) {extra}; an object has address, kind, count")
    kind, count = OBJECTS[name]
    address = entry.get("address")
    if type(address) is not int or not 0 <= address < ADDRESS_SPACE or address % 2:
        shown = oct(address) if type(address) is int else repr(address)
        raise MemoryMapError(f"{where}: address must be an even byte address 0..0o177776, not {shown}")
    if entry.get("kind", kind) != kind:
        raise MemoryMapError(f"{where}: kind must be {kind!r}, not {entry['kind']!r}")
    given = entry.get("count", count)
    least = name.startswith("jbuf")
    if type(given) is not int or (given < count if least else given != count):
        what = f"at least {count}" if least else str(count)
        raise MemoryMapError(f"{where}: count must be {what}, not {given!r}")
    obj = Region(name, kind, given, region(name).description, address)
    if obj.end > ADDRESS_SPACE:
        raise MemoryMapError(f"{where}: runs past the 16-bit address space (ends at {obj.end:#o})")
    return obj


def _check_overlaps(source: str, objects: Mapping[str, Region]) -> None:
    ordered = sorted(objects.values(), key=lambda o: o.address)
    for a, b in itertools.pairwise(ordered):
        if b.address < a.end:
            raise MemoryMapError(f"{source}: objects {a.name} and {b.name} overlap at {b.address:#o}")


def load_memory_map(path: Path) -> CougarMemoryMap:
    """The map in the file at ``path`` (read at most :data:`MAX_MAP_BYTES` + 1 bytes)."""
    try:
        with path.open("rb") as f:
            raw = f.read(MAX_MAP_BYTES + 1)
    except OSError as exc:
        raise MemoryMapError(f"{path}: cannot read it: {exc.strerror or exc}") from None
    if len(raw) > MAX_MAP_BYTES:
        raise MemoryMapError(f"{path}: larger than {MAX_MAP_BYTES} bytes")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise MemoryMapError(f"{path}: not UTF-8 text") from None
    return parse_memory_map(text, str(path))


def own_map(shift: int = 0) -> CougarMemoryMap:
    """manip's own map as declared (every object of :data:`OBJECTS`), moved up by ``shift`` bytes."""
    by_name = {r.name: r for r in MAP}
    objects = {name: replace(by_name[name], address=by_name[name].address + shift) for name in OBJECTS}
    source = "manip's own map" + (f", moved up {shift:#o} bytes" if shift else "")
    return CougarMemoryMap(objects, source)


def memory_map_toml(shift: int = 0) -> str:
    """manip's own map (moved up by ``shift`` bytes) as a memory map file."""
    lines = [
        "# The memory map of manip's simulated Cougar, in the format manip-conform run --cougar --memory-map",
        "# reads (docs/drv11j.md).  Byte addresses of 16-bit words, octal; floats are two words, the",
        "# sign/exponent word first; matrices row after row.",
        f"format = {FORMAT}",
        "",
        "[objects]",
    ]
    for obj in own_map(shift).objects.values():
        lines.append(
            f'{obj.name} = {{ address = 0o{obj.address:o}, kind = "{obj.kind}", count = {obj.count} }}'
        )
    return "\n".join(lines) + "\n"
