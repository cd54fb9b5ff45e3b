"""dissectors/manip.lua: generated from the spec data, and in real tshark it agrees with manip-decode
field for field on every packet of the golden captures (exported to pcapng by manip-capture export).

tshark is Debian's package (.ci/run installs it).  Without it these tests are skipped, except in CI
(``CI=true``), where a missing tshark is a failure: the dissector must never go untested there.
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
import shutil
import subprocess
from collections import defaultdict
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest
from click.testing import CliRunner

from manip.captures.pcap import export_pcapng
from manip.decode.cli import main as decode_main

ROOT = Path(__file__).resolve().parents[1]
LUA = ROOT / "dissectors" / "manip.lua"
GOLDEN = ("describe-self", "motion", "errors")
TSHARK = shutil.which("tshark")


def _generator() -> ModuleType:
    spec = importlib.util.spec_from_file_location("gen_dissector", ROOT / "tools" / "gen_dissector.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_generated_dissector_is_current() -> None:
    assert LUA.read_text() == _generator().render(), "run: python tools/gen_dissector.py"


def test_dissector_tables_come_from_the_spec() -> None:
    from manip.spec import SPEC

    text = LUA.read_text()
    for op in SPEC.requests.values():
        assert f'[{op.opcode}] = {{name = "{op.name}"' in text
    for code in SPEC.error_codes:
        assert f'["{code}"] = ' in text


def _need_tshark() -> str:
    if TSHARK is None:
        if os.environ.get("CI") == "true":
            pytest.fail("tshark is not installed: .ci/run installs Debian's tshark package")
        pytest.skip("tshark is not installed (apt-get install tshark)")
    return TSHARK


# ---------------------------------------------------------------------------------------- tshark side


def _collect(node: Any, out: dict[str, list[str]]) -> None:
    if isinstance(node, dict):
        for key, value in node.items():
            if key.startswith("_ws.expert") or key.startswith("_ws.malformed"):
                continue
            if key.startswith(("chaos.", "manip.")) and not key.endswith("_tree"):
                values = value if isinstance(value, list) else [value]
                if all(isinstance(v, str) for v in values):
                    out[key].extend(values)
                    continue
            _collect(value, out)
    elif isinstance(node, list):
        for item in node:
            _collect(item, out)


def tshark_fields(pcapng: Path) -> list[dict[str, list[str]]]:
    """Each packet's chaos.* and manip.* fields as tshark with the dissector shows them."""
    result = subprocess.run(
        [_need_tshark(), "-X", f"lua_script:{LUA}", "-r", str(pcapng), "-T", "json", "--no-duplicate-keys"],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "Lua" not in result.stderr and "error" not in result.stderr.lower(), result.stderr
    packets = []
    for packet in json.loads(result.stdout):
        fields: dict[str, list[str]] = defaultdict(list)
        _collect(packet["_source"]["layers"], fields)
        packets.append(dict(fields))
    return packets


# ---------------------------------------------------------------------------------------- manip-decode side


def _key(label: str) -> str:
    return label.replace(" ", "_")


def _add(out: dict[str, list[Any]], key: str, value: Any) -> None:
    if isinstance(value, list):
        out[key].extend(value)
    else:
        out[key].append(value)


def expected_fields(packet: dict[str, Any]) -> tuple[dict[str, list[Any]], bool]:
    """manip-decode's JSON tree of one packet as dissector fields; and whether the manip layer failed."""
    out: dict[str, list[Any]] = defaultdict(list)
    broken = False
    for section in packet["children"]:
        label = section["label"]
        if label == "chaos header":
            for child in section["children"]:
                value = child.get("value")
                if isinstance(value, dict):
                    for k, v in value.items():
                        _add(out, f"chaos.{_key(child['label'])}_{k}", v)
                else:
                    _add(out, f"chaos.{_key(child['label'])}", value)
        elif label in ("rfc", "opn", "sts", "cls", "los", "ans", "fwd"):
            if "value" in section:
                _add(out, "chaos.text", section["value"])
            for child in section.get("children", []):
                _add(out, f"chaos.{_key(child['label'])}", child["value"])
        elif label == "data":
            _add(out, "chaos.data", section["value"])
        elif label == "decode error":
            broken = True
            out["manip.clause"].append(section["value"]["clause"])
        else:
            assert label.startswith("manip "), label
            children = {_key(c["label"]) for c in section.get("children", [])}
            for k, v in section.get("value", {}).items():
                if k not in children:
                    _add(out, f"manip.{k}", v)
            for child in section.get("children", []):
                if child["label"] == "decode error":
                    broken = True
                    out["manip.clause"].append(child["value"]["clause"])
                elif "value" in child:
                    _add(out, f"manip.{_key(child['label'])}", child["value"])
    return dict(out), broken


def _same(shown: str, value: Any) -> bool:
    if isinstance(value, bool):
        return shown == str(int(value))
    if isinstance(value, int):
        return int(shown, 0) == value
    if isinstance(value, float):
        return math.isclose(float(shown), value, rel_tol=1e-13, abs_tol=1e-300)
    return bool(shown == value)


def compare(expected: dict[str, list[Any]], broken: bool, shown: dict[str, list[str]]) -> list[str]:
    """Every difference between the two sides, as readable lines (empty when they agree)."""
    problems = []
    keys = set(expected) | set(shown)
    if broken:  # the dissector may show what it could read before the error; manip-decode shows none
        keys = {k for k in keys if k.startswith("chaos.")} | {"manip.clause"}
        if "manip.decode_error" not in shown:
            problems.append("manip.decode_error: missing in tshark")
    for key in sorted(keys):
        want, got = expected.get(key, []), shown.get(key, [])
        if len(want) != len(got) or not all(_same(g, w) for g, w in zip(got, want, strict=True)):
            problems.append(f"{key}: manip-decode {want!r}, tshark {got!r}")
    return problems


def _decoded(pcapng: Path) -> list[dict[str, Any]]:
    result = CliRunner().invoke(decode_main, ["--pcap", str(pcapng), "--format", "json"])
    assert result.exit_code in (0, 1), result.output
    packets: list[dict[str, Any]] = json.loads(result.stdout)
    return packets


def test_the_comparison_can_fail() -> None:
    expected = {"chaos.opcode": [1], "manip.joints": [1.5, -90.0]}
    assert compare(expected, False, {"chaos.opcode": ["1"], "manip.joints": ["1.5", "-90"]}) == []
    assert compare(expected, False, {"chaos.opcode": ["1"], "manip.joints": ["1.5", "-90.001"]})
    assert compare(expected, False, {"chaos.opcode": ["1"], "manip.joints": ["1.5"]})
    assert compare(expected, False, {"chaos.opcode": ["1"], "manip.joints": ["1.5", "-90"], "manip.x": ["1"]})


@pytest.mark.parametrize("name", GOLDEN)
def test_tshark_agrees_with_manip_decode_on_golden_captures(tmp_path: Path, name: str) -> None:
    _need_tshark()
    pcapng = tmp_path / f"{name}.pcapng"
    export_pcapng(ROOT / "captures" / f"{name}.mcap", pcapng)
    decoded = _decoded(pcapng)
    shown = tshark_fields(pcapng)
    assert len(shown) == len(decoded) > 10
    manip_fields = 0
    for number, (packet, fields) in enumerate(zip(decoded, shown, strict=True), 1):
        assert packet["label"] == f"packet {number}"
        expected, broken = expected_fields(packet)
        problems = compare(expected, broken, fields)
        assert not problems, f"{name} packet {number}:\n  " + "\n  ".join(problems)
        manip_fields += sum(len(v) for k, v in fields.items() if k.startswith("manip."))
    assert manip_fields > 20  # the manip layer was there to compare, not just Chaos headers
