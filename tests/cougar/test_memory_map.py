"""The memory map file format (``manip.cougar.memory_map``): manip's own map round trip, the example the
repository ships, and a clear error for each way a file can be wrong."""

from __future__ import annotations

from pathlib import Path

import pytest

from manip.cougar import CougarConfig, CougarSim
from manip.cougar.memory import region
from manip.cougar.memory_map import (
    MAX_MAP_BYTES,
    OBJECTS,
    MemoryMapError,
    load_memory_map,
    memory_map_toml,
    own_map,
    parse_memory_map,
)
from manip.cougar.readings import MAP_SHIFT
from manip.spec.constants import CougarCommand
from tests.support.paths import ROOT


def test_own_map_round_trips_through_the_file_format() -> None:
    for shift in (0, MAP_SHIFT):
        parsed = parse_memory_map(memory_map_toml(shift))
        assert dict(parsed.objects) == dict(own_map(shift).objects)
    assert parse_memory_map(memory_map_toml()).objects["k"].address == region("k").address == 0o1144


def test_the_example_map_is_manips_own() -> None:
    shipped = ROOT / "examples" / "cougar-memory-map.toml"
    assert shipped.read_text() == memory_map_toml(), "regenerate: manip-cougar --print-memory-map"
    assert set(load_memory_map(shipped).objects) == set(OBJECTS)


def test_a_relocated_cougar_is_where_its_map_says() -> None:
    sim = CougarSim(CougarConfig(readings=frozenset({"relocated-map"})), seed=1)
    version = own_map(MAP_SHIFT).objects["version"]
    sim.receive([CougarCommand.EXMN, version.address, 1, CougarCommand.EXMN, 0, 1])
    out = sim.tick(0.0)
    assert out[:3] == [4, 1, CougarConfig().version]
    assert out[3:5] == [4, 1]  # address 0 is memory still (the vectors stay put)
    sim.receive([CougarCommand.DPST, version.address, 0o123, CougarCommand.VERS, 1])
    assert sim.tick(1.0) == [8, 0o123]


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("format = 1\n[objects]\nk = { address = 0o1145 }\n", "even byte address"),
        ("format = 1\n[objects]\nk = { address = -2 }\n", "even byte address"),
        ("format = 1\n[objects]\nk = { address = 0o177770 }\n", "past the 16-bit address space"),
        ('format = 1\n[objects]\nk = { address = 0o1000, kind = "word" }\n', "kind must be 'float'"),
        ("format = 1\n[objects]\nk = { address = 0o1000, count = 7 }\n", "count must be 6"),
        ("format = 1\n[objects]\njbuf0 = { address = 0o1000, count = 35 }\n", "at least 36"),
        ("format = 1\n[objects]\nk = { address = 0o1000, size = 1 }\n", "unknown key"),
        ("format = 1\n[objects]\nwhatever = { address = 0o1000 }\n", "not an object the cases use"),
        ("format = 1\n[objects]\nk = 0o1000\n", "needs a table"),
        ("format = 1\n[objects]\nk = { address = 0o1000 }\nbji = { address = 0o1020 }\n", "overlap"),
        ("[objects]\nk = { address = 0o1000 }\n", "format = 1"),
        ("format = 1\n", "[objects]"),
        ("format = 1\nextra = 2\n[objects]\nk = { address = 0o1000 }\n", "unknown key"),
        ("format = 1\n[objects\n", "not TOML"),
    ],
)
def test_a_wrong_map_says_what_and_where(text: str, says: str) -> None:
    with pytest.raises(MemoryMapError, match=r"my\.toml") as info:
        parse_memory_map(text, "my.toml")
    assert says in str(info.value)


def test_a_map_file_is_read_within_its_bound(tmp_path: Path) -> None:
    big = tmp_path / "big.toml"
    big.write_text("#" * (MAX_MAP_BYTES + 10))
    with pytest.raises(MemoryMapError, match="larger than"):
        load_memory_map(big)
    binary = tmp_path / "bin.toml"
    binary.write_bytes(b"\xff\xfe")
    with pytest.raises(MemoryMapError, match="UTF-8"):
        load_memory_map(binary)
    with pytest.raises(MemoryMapError, match="cannot read"):
        load_memory_map(tmp_path / "absent.toml")
