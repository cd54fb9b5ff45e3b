"""The standard-library example harness (examples/stdlib_harness.py): it imports nothing but the
standard library, its PDP-11 float codec and error-string parsing agree with manip's on the project's
vectors and on drawn values, and it talks to the reference server through the harness contract."""

from __future__ import annotations

import ast
import asyncio
import importlib.util
import json
import math
import socket
import struct
import subprocess
import sys
import time
from importlib import resources
from types import ModuleType
from typing import Any
from urllib.parse import urlsplit, urlunsplit

import pytest
from hypothesis import given
from hypothesis import strategies as st

from manip.codecs.errors import CodecError
from manip.codecs.framing import TcpFrameDecoder, encode_tcp
from manip.codecs.packet import Packet
from manip.codecs.pdp11float import F_MAX, F_MIN_NORMAL, f_to_u32, u32_to_f
from manip.conformance.client.cli import client_cases
from manip.conformance.client.runner import ClientRunConfig, run_client_suite
from manip.conformance.suite.context import RunOptions
from manip.conformance.suite.results import ExitCode
from tests.support.paths import ROOT

HARNESS = ROOT / "examples" / "stdlib_harness.py"
DEFAULT_POLICY = {"underflow": "zero", "dirty_zero": "zero", "reserved": "error"}


def _load() -> ModuleType:
    spec = importlib.util.spec_from_file_location("stdlib_harness", HARNESS)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


H = _load()


def _vectors(name: str) -> list[dict[str, Any]]:
    text = resources.files("manip.vectors").joinpath(name).read_text()
    vectors: list[dict[str, Any]] = json.loads(text)["vectors"]
    return vectors


# ----------------------------------------------------------------------------- standard library only


def test_the_harness_imports_only_the_standard_library() -> None:
    tree = ast.parse(HARNESS.read_text())
    imported: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            imported.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            assert node.level == 0, "a relative import"
            imported.add((node.module or "").split(".")[0])
    assert imported, "the parse found no imports at all"
    assert not imported - set(sys.stdlib_module_names) - {"__future__"}


def test_loading_the_harness_without_site_packages_loads_only_the_standard_library() -> None:
    # -I -S: no site-packages on the path, so neither manip nor any third-party package can load.
    probe = (
        "import json, runpy, sys; runpy.run_path(sys.argv[1], run_name='probe'); "
        "print(json.dumps(sorted({name.split('.')[0] for name in sys.modules})))"
    )
    command = [sys.executable, "-I", "-S", "-c", probe, str(HARNESS)]
    done = subprocess.run(command, check=False, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    loaded = set(json.loads(done.stdout))
    assert "socket" in loaded  # the probe saw the harness's own imports
    assert not loaded - set(sys.stdlib_module_names) - {"__main__", "__future__"}


# ----------------------------------------------------------------------------- PDP-11 F floats


def _encode(x: float) -> int | None:
    """The harness's encoding as manip's uint32 (word 0 low), or None when it refuses the value."""
    try:
        w0, w1 = H.f_encode(x)
    except ValueError:
        return None
    return int(w0 | w1 << 16)


def _manip_encode(x: float) -> int | None:
    try:
        return f_to_u32(x)
    except CodecError:
        return None


def _decode(u: int) -> float | None:
    try:
        return float(H.f_decode(u & 0xFFFF, u >> 16))
    except H.ReservedOperandError:
        return None


def _manip_decode(u: int) -> float | None:
    try:
        return u32_to_f(u)
    except CodecError:
        return None


def _bits(x: float | None) -> bytes | None:
    """Bit-exact comparison: 0.0 and -0.0 differ here."""
    return None if x is None else struct.pack("<d", x)


def _defaults_apply(vector: dict[str, Any]) -> bool:
    """The vector holds for the harness's fixed choices (half even, flush to zero, reserved an error)."""
    rounding = vector.get("rounding")
    policy = vector.get("policy", {})
    return (rounding is None or "half-even" in rounding) and all(
        DEFAULT_POLICY[k] == v for k, v in policy.items()
    )


FLOAT_VECTORS = [v for v in _vectors("float.json") if _defaults_apply(v)]


@pytest.mark.parametrize("vector", FLOAT_VECTORS, ids=[v["name"] for v in FLOAT_VECTORS])
def test_float_vectors(vector: dict[str, Any]) -> None:
    u = int.from_bytes(bytes.fromhex(vector["hex"]), "little") if "hex" in vector else None
    if vector["direction"] in ("both", "encode"):
        x = float.fromhex(vector["value_hex"])
        assert _encode(x) == (None if "error" in vector else u)
        assert _encode(x) == _manip_encode(x)
    if vector["direction"] in ("both", "decode"):
        assert u is not None
        expected = None if "error" in vector else float.fromhex(vector["value_hex"])
        assert _bits(_decode(u)) == _bits(expected)
        assert _bits(_decode(u)) == _bits(_manip_decode(u))


def test_the_float_vectors_cover_the_edges() -> None:
    names = {v["name"] for v in FLOAT_VECTORS}
    assert {"max", "min", "zero", "minus-zero", "reserved-operand", "dirty-zero", "tie-half-even"} <= names


# Values at and around the edges, and ties: a 25-bit significand with its last bit set is exactly
# half-way between two F floats.
EDGES = [F_MAX, F_MIN_NORMAL, math.nextafter(F_MIN_NORMAL, 0.0), F_MIN_NORMAL * (1 - 2**-25), 0.0, -0.0]
EDGES += [F_MIN_NORMAL * (1 - 2**-24), F_MIN_NORMAL * 0.75, F_MIN_NORMAL / 2]  # just too small: zero
EDGES += [F_MAX * (1 + 2**-25), math.nextafter(F_MAX * (1 + 2**-25), 0.0), 2.0**127, math.inf, math.nan]
any_float = st.floats(allow_nan=True, allow_infinity=True)
ties = st.builds(math.ldexp, st.integers(2**24, 2**25 - 1), st.integers(-160, 110))
edges = st.sampled_from(EDGES + [-x for x in EDGES])


@given(st.one_of(any_float, ties, edges, ties.map(lambda x: -x)))
def test_float_encoding_agrees_with_manip_bit_for_bit(x: float) -> None:
    assert _encode(x) == _manip_encode(x)


# Every exponent 0 pattern (zero, dirty zero, the reserved operand) and the largest and smallest ones.
patterns = st.builds(lambda w0, w1: w0 | w1 << 16, st.integers(0, 0xFFFF), st.integers(0, 0xFFFF))
zero_exponent = st.builds(lambda s, f: s | f, st.sampled_from([0, 0x8000]), st.integers(0, 0xFFFF007F))
edge_patterns = st.sampled_from([0, 0x8000, 0xFFFF7FFF, 0xFFFFFFFF, 0x80, 0x8080, 0x00008000])


@given(st.one_of(patterns, zero_exponent, edge_patterns))
def test_float_decoding_agrees_with_manip_bit_for_bit(u: int) -> None:
    assert _bits(_decode(u)) == _bits(_manip_decode(u))


# ----------------------------------------------------------------------------- error strings

ERROR_VECTORS = [v for v in _vectors("error_strings.json") if "error" not in v]


@pytest.mark.parametrize("vector", ERROR_VECTORS, ids=[v["name"] for v in ERROR_VECTORS])
def test_error_string_vectors(vector: dict[str, Any]) -> None:
    parts = H.parse_error(bytes.fromhex(vector["hex"]))
    decoded = vector["decoded"]
    got = {k: parts[k] for k in ("where", "severity", "code", "template", "arguments")}
    want = {k: decoded[k] for k in ("where", "severity", "code", "message", "args")}
    assert list(got.values()) == list(want.values())
    assert parts["rendered"] == vector["rendered"]


def test_error_vectors_include_both_argument_layouts() -> None:
    names = {v["name"] for v in ERROR_VECTORS}
    assert {"guide-nzi-example-aligned", "guide-nzi-example-unaligned", "mask-and-tilde"} <= names


@pytest.mark.parametrize(
    ("mask", "words"), [(0, "none"), (4, "3"), (6, "2 and 3"), (35, "1, 2 and 6"), (0x8001, "1 and 16")]
)
def test_joint_masks_in_english(mask: int, words: str) -> None:
    assert H.joint_list(mask) == words


# ----------------------------------------------------------------------------- TCP link framing, NCP

word = st.integers(0, 0xFFFF)
packets = st.builds(
    Packet, st.sampled_from([1, 2, 3, 7, 9, 0o14, 0o200, 0o203, 0o377]), word, word, word, word, word, word,
    st.binary(max_size=488),
)  # fmt: skip


def _mine(p: Packet) -> Any:
    return H.Packet(
        p.opcode, p.dest_host, p.dest_index, p.src_host, p.src_index, p.packet_no, p.ack_no, p.data
    )


@given(packets, st.integers(0, 600))
def test_tcp_frames_agree_with_manip_both_ways(p: Packet, cut: int) -> None:
    frame = encode_tcp(p)
    assert H.encode_frame(_mine(p)) == frame
    reader = H.FrameReader()
    got = reader.feed(frame[:cut]) + reader.feed(frame[cut:] + frame)  # in pieces, then a whole one
    assert got == [_mine(p), _mine(p)]


def test_a_garbled_frame_is_dropped_and_the_next_one_read() -> None:
    p = Packet(0o200, 0o401, 7, 0o440, 9, 5, 4, b"abc")
    garbled = bytearray(encode_tcp(p))
    garbled[20] ^= 0x10  # a data bit: the checksum no longer holds
    assert H.FrameReader().feed(bytes(garbled) + encode_tcp(p)) == [_mine(p)]


def _frames(sock: socket.socket) -> list[Packet]:
    """Every frame the harness wrote so far, decoded by manip's decoder."""
    sock.settimeout(0.2)
    decoder, out = TcpFrameDecoder(), []
    try:
        while chunk := sock.recv(65536):
            out += [item for item in decoder.feed(chunk) if isinstance(item, Packet)]
    except TimeoutError:
        pass
    return out


def test_the_ncp_orders_receipts_and_stops_resending_across_the_wrap() -> None:
    ours, theirs = socket.socketpair()
    delivered: list[int] = []
    ended: list[str] = []
    conn = H.Connection(ours, 0o401, 0o440, lambda p: delivered.append(p.number), ended.append)
    conn.next_number = conn.acked = 0xFFFE  # our numbers wrap too: RFC 0xFFFE, then 0xFFFF, 0x0000
    try:
        conn.send_controlled(H.RFC, b"PUMA")
        (rfc,) = _frames(theirs)
        assert (rfc.opcode, rfc.data, rfc.dest_host, rfc.src_host, rfc.packet_no) == (
            1,
            b"PUMA",
            0o440,
            0o401,
            0xFFFE,
        )

        def send(opcode: int, number: int, ack: int, data: bytes = b"") -> None:
            theirs.sendall(encode_tcp(Packet(opcode, 0o401, rfc.src_index, 0o440, 0o1234, number, ack, data)))
            conn.poll(time.monotonic() + 0.2)

        send(2, 0xFFFD, 0xFFFE, struct.pack("<HH", 0xFFFE, 5))  # OPN, the server's numbers about to wrap
        assert conn.state == "open" and _frames(theirs)[-1].opcode == 7  # answered with STS
        for number in (0xFFFE, 0x0000, 0x0001, 0xFFFF, 0xFFFE):  # out of order, then a duplicate
            send(0o200, number, 0xFFFE, b"\0\0")
        assert delivered == [0xFFFE, 0xFFFF, 0x0000, 0x0001]
        last = _frames(theirs)[-1]
        assert (last.opcode, last.ack_no, last.data) == (7, 0x0001, b"\1\0" + bytes([H.WINDOW, 0]))

        sent = [conn.send_controlled(0o201, b""), conn.send_controlled(H.EOF, b"")]
        assert sent == [0xFFFF, 0x0000] and [p.packet_no for p in _frames(theirs)] == sent
        send(7, 0x0002, 0x0000, struct.pack("<HH", 0x0000, 5))  # STS: both receipted
        assert not conn.unreceipted
        time.sleep(H.RESEND_AFTER)
        conn.poll(time.monotonic() + 0.1)
        assert _frames(theirs) == []  # nothing resent
        send(3, 0x0002, 0x0000, b"Puma going away")  # CLS
        assert ended == ["closed by the server: Puma going away"] and conn.state == "ended"
    finally:
        conn.abort()
        theirs.close()


# ----------------------------------------------------------------------------- against the reference server


def _run(lines: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Run the harness on ``lines`` without site-packages; every line it writes, parsed."""
    stdin = "".join(json.dumps(line) + "\n" for line in lines)
    command = [sys.executable, "-I", "-S", str(HARNESS)]
    done = subprocess.run(command, check=False, input=stdin, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    return [json.loads(line) for line in done.stdout.splitlines()]


def _target(server_url: str) -> str:
    parts = urlsplit(server_url)
    query = "&".join(q for q in [parts.query, "me=0401&addr=0440"] if q)
    return urlunsplit((parts.scheme, parts.netloc, parts.path, query, ""))


@pytest.mark.parametrize("server", ["reference_server_url", "chudp_server_url"], ids=["tcp", "chudp"])
def test_a_session_with_the_reference_server(server: str, request: pytest.FixtureRequest) -> None:
    reference_server_url = request.getfixturevalue(server)
    jor = {"joints": [0.0, -90.0, 300.0, 0.0, 0.0, 300.0]}  # joints 3 and 6 beyond their limits
    ops = [
        {"op": "connect"},
        {"op": "describe-self"},
        {"op": "here"},
        {"op": "joint-angles"},
        {"op": "enable-power"},
        {"op": "set-joint-angles", "args": jor},
        {"op": "read-forces"},
        {"op": "close"},
        {"op": "here"},
    ]
    case = {"type": "case", "contract": 1, "case": "example.session", "seed": 1,
            "link": urlsplit(reference_server_url).scheme,
            "target": _target(reference_server_url), "contact": "PUMA", "timeout": 5.0,
            "operations": [{"id": i, **op} for i, op in enumerate(ops)]}  # fmt: skip
    hello, *results = _run([case])

    assert hello["type"] == "hello" and hello["contract"] == 1
    assert "read-forces" not in hello["operations"] and "here" in hello["operations"]
    assert all(r["case"] == "example.session" for r in results)
    by_op = {r.get("op"): r for r in results}
    assert [r["type"] for r in results] == [
        "state", "reply", "reply", "reply", "reply", "error", "unsupported", "state", "error", "done"
    ]  # fmt: skip
    assert by_op[0]["state"] == "connected"

    text = by_op[1]["values"]["text"]
    assert text.startswith("((:") and "(:PROTOCOL-VERSION . 1)" in text
    assert bytes.fromhex(by_op[1]["raw"]["text"]).replace(b"\x8d", b"\n").decode() == text

    transform = by_op[2]["values"]["transform"]
    assert len(transform) == 12 and transform[:9] == [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    assert by_op[3]["values"]["joints"] == [0.0, -90.0, 90.0, 0.0, 0.0, 0.0]  # the ready position
    assert by_op[3]["raw"]["joints"][1] == "C3B40000"  # -90.0
    for r in (by_op[2], by_op[3]):  # each value is the exact decoding of its raw bits
        for value, raw in zip(*r["values"].values(), *r["raw"].values(), strict=True):
            assert value == u32_to_f(int(raw[:4], 16) | int(raw[4:], 16) << 16)
    numbers = [by_op[i]["request_number"] for i in range(1, 6)]
    assert numbers == [(numbers[0] + i) & 0xFFFF for i in range(5)]  # consecutive packet numbers

    error = by_op[5]
    assert (error["origin"], error["severity"], error["code"]) == ("non-fatal-error", "E", "JOR")
    assert error["arguments"] == [0b100100] and "$" in error["template"]
    assert error["message"] == error["template"].replace("$", "3 and 6")
    assert error["rendered"] == f"{error['where']}: E JOR {error['message']}"

    assert by_op[6] == {"type": "unsupported", "case": "example.session", "op": 6, "operation": "read-forces"}
    assert by_op[7]["state"] == "closed"
    assert (by_op[8]["origin"], by_op[8]["kind"]) == ("client", "not-connected")


def test_a_refused_connection_and_end_of_input(reference_server_url: str) -> None:
    case = {"type": "case", "case": "example.refused", "target": _target(reference_server_url),
            "contact": "NO-SUCH-CONTACT", "timeout": 5.0,
            "operations": [{"id": 0, "op": "connect"}, {"id": 1, "op": "here"}]}  # fmt: skip
    _hello, refused, not_connected, done = _run([case])
    assert (refused["state"], refused["op"]) == ("refused", 0) and refused["reason"]
    assert not_connected["kind"] == "not-connected"
    assert done == {"type": "done", "case": "example.refused"}


# ----------------------------------------------------------------------------- judged by the suite

NEW_CASES = (
    "client.ncp.window",
    "client.ncp.window-opens-late",
    "client.ncp.window-shrinks",
    "client.pipeline.interleaved",
)
"""The judge's window and interleaving cases: the example pipelines, so each runs and must pass."""


@pytest.mark.waits
@pytest.mark.parametrize("link", ["tcp", "chudp"])
def test_the_judge_passes_the_example_on_each_link(link: str) -> None:
    """``manip-conform client --link LINK -- python3 examples/stdlib_harness.py``, every case: none
    fails, the new window and interleaving cases pass, and what it does not declare is unsupported."""
    config = ClientRunConfig(
        argv=[sys.executable, str(HARNESS)], link=link, seed=1985, options=RunOptions(reply_timeout=1.0)
    )
    report = asyncio.run(run_client_suite(config, client_cases()))
    got = {r.id: r.outcome for r in report.results}
    failed = {r.id: [str(v) for v in r.violations] or r.reason for r in report.results if r.outcome == "fail"}
    assert report.exit_code == ExitCode.CONFORMANT and not failed, failed
    assert {got[c] for c in NEW_CASES} == {"pass"}, {c: got[c] for c in NEW_CASES}
    assert got["client.choice.guard-numbers"] == "unsupported"  # no wrist extensions
    assert got["client.chudp.duplicate-reorder"] == ("pass" if link == "chudp" else "skip")
