"""dissectors/manip.lua: generated from the spec data, and in real tshark it agrees with manip-decode
field for field on every packet of the golden captures (exported to pcapng by manip-capture export), and
of a capture that starts after its connection opened (no RFC: the sides come from the packets' shape).

The same captures go through the dissector in a plain Lua 5.4 interpreter
(``tests/decode/lua/wireshark_stub.lua`` stands in for Wireshark's API), as Wireshark 4.4 and later run
it, and in Lua 5.2 (what Debian's tshark runs it on): the dissector must not need ``bit32`` nor the
bitwise operators.

tshark, lua5.4 and lua5.2 are Debian's packages (.ci/run installs them).  Without them these tests are
skipped, and the run's last line says so, except under ``MANIP_REQUIRE_PROGRAMS=1`` (set by .ci/run),
where a missing one is a failure: the dissector must never go untested there (the one rule of
``tests/support/programs.py``).
"""

from __future__ import annotations

import json
import math
import re
import subprocess
from collections import defaultdict
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest
from click.testing import CliRunner

from manip.captures.pcap import export_pcapng, iter_datagrams
from manip.decode.cli import main as decode_main
from tests.support.paths import ROOT
from tests.support.programs import need_program
from tests.support.tools import load_tool

LUA = ROOT / "dissectors" / "manip.lua"
GOLDEN = ("describe-self", "motion", "errors")
STUB = Path(__file__).parent / "lua" / "wireshark_stub.lua"
LUAS = ("lua5.4", "lua5.2")


def _generator() -> ModuleType:
    return load_tool("gen_dissector")


def test_generated_dissector_is_current() -> None:
    assert LUA.read_text() == _generator().render(), "run: python tools/gen_dissector.py"


def test_dissector_tables_come_from_the_spec() -> None:
    from manip.spec import SPEC

    text = LUA.read_text()
    for op in SPEC.requests.values():
        assert f'[{op.opcode}] = {{name = "{op.name}"' in text
    for code in SPEC.error_codes:
        assert f'["{code}"] = ' in text


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
    tshark = need_program("tshark")
    result = subprocess.run(
        [tshark, "-X", f"lua_script:{LUA}", "-r", str(pcapng), "-T", "json", "--no-duplicate-keys"],
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


def lua_fields(lua: str, pcapng: Path, tmp_path: Path) -> list[dict[str, list[str]]]:
    """Each packet's chaos.* and manip.* fields as the dissector adds them in a plain Lua interpreter."""
    datagrams = tmp_path / f"{pcapng.stem}.datagrams"
    datagrams.write_text(
        "".join(f"{d.src[1]} {d.dst[1]} {d.payload.hex()}\n" for d in iter_datagrams(pcapng)),
        encoding="ascii",
    )
    result = subprocess.run(
        [lua, str(STUB), str(LUA), str(datagrams)], capture_output=True, text=True, timeout=60, check=False
    )
    assert result.returncode == 0 and not result.stderr, result.stderr[-3000:]
    packets: list[dict[str, list[str]]] = [defaultdict(list)]
    for line in result.stdout.splitlines():
        if line == "--":
            packets.append(defaultdict(list))
            continue
        key, _, value = line.partition("\t")
        packets[-1][key].append(_unescape(value))
    assert not packets.pop(), "output after the last packet"
    return [dict(p) for p in packets]


def _unescape(text: str) -> str:
    return re.sub(r"\\(.)", lambda m: {"t": "\t", "n": "\n", "r": "\r"}.get(m.group(1), m.group(1)), text)


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


def _agrees(name: str, decoded: list[dict[str, Any]], shown: list[dict[str, list[str]]]) -> None:
    """The dissector's fields are manip-decode's, packet for packet, and the manip layer was there."""
    assert len(shown) == len(decoded) > 5
    manip_fields = 0
    for number, (packet, fields) in enumerate(zip(decoded, shown, strict=True), 1):
        assert packet["label"] == f"packet {number}"
        expected, broken = expected_fields(packet)
        problems = compare(expected, broken, fields)
        assert not problems, f"{name} packet {number}:\n  " + "\n  ".join(problems)
        manip_fields += sum(len(v) for k, v in fields.items() if k.startswith("manip."))
    assert manip_fields > 20  # the manip layer was there to compare, not just Chaos headers


def _golden(name: str, tmp_path: Path) -> Path:
    pcapng = tmp_path / f"{name}.pcapng"
    export_pcapng(ROOT / "captures" / f"{name}.mcap", pcapng)
    return pcapng


def mid_connection_capture(tmp_path: Path) -> Path:
    """A capture that starts after the connection opened: no RFC, no OPN, a move request (0204, 48
    bytes, which by opcode alone could be an asynchronous error) first, then replies, errors and more
    requests between a client and a server on CHUDP's port."""
    import socket

    import dpkt

    from manip.codecs import ErrorMessage, Packet, encode_chudp, encode_reply, encode_request
    from manip.codecs.messages import encode_error
    from manip.spec.constants import ServerOp

    client, server = ("127.0.1.1", 42042), ("127.0.0.1", 42042)
    pose = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 500.0, 150.0, 400.0]
    nap = ErrorMessage("move", "E", "NAP", "No arm power", ())
    exchange = [
        (True, 0o204, 40, encode_request("move", transform=pose)),
        (False, ServerOp.NON_FATAL_ERROR, 50, encode_error(ServerOp.NON_FATAL_ERROR, 40, nap)),
        (True, 0o201, 41, b""),
        (False, ServerOp.RESPONSE, 51, encode_reply("here", 41, transform=pose)),
        (True, 0o202, 42, b""),
        (
            False,
            ServerOp.RESPONSE,
            52,
            encode_reply("joint-angles", 42, joints=(5.0, -95.0, 92.5, 0.0, 4.0, -3.0)),
        ),
        (True, 0o204, 43, encode_request("move", transform=pose)),
        (False, ServerOp.NON_FATAL_ERROR, 53, encode_error(ServerOp.NON_FATAL_ERROR, 43, nap)),
    ]
    path = tmp_path / "mid-connection.pcap"
    with path.open("wb") as f:
        writer = dpkt.pcap.Writer(f, linktype=dpkt.pcap.DLT_RAW)
        for i, (to_server, opcode, number, data) in enumerate(exchange):
            (dh, di), (sh, si) = (
                ((0o440, 0x5E02), (0o401, 0x0A01)) if to_server else ((0o401, 0x0A01), (0o440, 0x5E02))
            )
            payload = encode_chudp(Packet(opcode, dh, di, sh, si, number, 0, data))
            src, dst = (client, server) if to_server else (server, client)
            udp = dpkt.udp.UDP(sport=src[1], dport=dst[1], data=payload, ulen=8 + len(payload))
            ip = dpkt.ip.IP(
                src=socket.inet_aton(src[0]), dst=socket.inet_aton(dst[0]), p=dpkt.ip.IP_PROTO_UDP,
                ttl=64, id=i, data=udp, len=28 + len(payload),
            )  # fmt: skip
            writer.writepkt(bytes(ip), ts=1_700_000_000 + i / 100)
    return path


CAPTURES = (*GOLDEN, "mid-connection")


def _capture(name: str, tmp_path: Path) -> Path:
    return mid_connection_capture(tmp_path) if name == "mid-connection" else _golden(name, tmp_path)


@pytest.mark.parametrize("name", CAPTURES)
def test_tshark_agrees_with_manip_decode(tmp_path: Path, name: str) -> None:
    need_program("tshark")
    capture = _capture(name, tmp_path)
    _agrees(name, _decoded(capture), tshark_fields(capture))


@pytest.mark.parametrize("lua", LUAS)
@pytest.mark.parametrize("name", CAPTURES)
def test_plain_lua_agrees_with_manip_decode(tmp_path: Path, name: str, lua: str) -> None:
    """Lua 5.4 (Wireshark 4.4 and later) and 5.2 (Debian's tshark) run the one file alike."""
    interpreter = need_program(lua)
    capture = _capture(name, tmp_path)
    _agrees(name, _decoded(capture), lua_fields(interpreter, capture, tmp_path))


def test_a_move_request_without_its_rfc_is_a_request(tmp_path: Path) -> None:
    """The case that once read a move (0204, 48 bytes) as an asynchronous error to #16504, malformed."""
    interpreter = need_program("lua5.4")
    first = lua_fields(interpreter, mid_connection_capture(tmp_path), tmp_path)[0]
    assert first["manip.name"] == ["move"] and "manip.decode_error" not in first, first
    assert [float(v) for v in first["manip.transform"]][-3:] == [500.0, 150.0, 400.0]
