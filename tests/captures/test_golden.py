"""The golden captures in captures/: readable, what they claim to hold, and the same when made again."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner
from mcap.reader import make_reader

from manip.captures import read_capture, read_session
from manip.captures.cli import main as capture_main
from manip.decode.cli import main as decode_main
from manip.spec import SPEC
from tests.support.paths import ROOT
from tests.support.tools import load_tool

GOLDEN = ROOT / "captures"
NAMES = ("describe-self", "motion", "errors")


@pytest.fixture(scope="module")
def remade(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("remade")
    subprocess.run(
        [sys.executable, str(ROOT / "tools" / "make_captures.py"), "--out", str(out)],
        check=True, capture_output=True, timeout=90,
    )  # fmt: skip
    return out


@pytest.mark.parametrize("name", NAMES)
def test_golden_capture_is_readable_and_complete(name: str) -> None:
    capture = read_capture(GOLDEN / f"{name}.mcap")
    assert capture.metadata["manip.capture"]["spec_revision"] == SPEC.revision
    assert capture.metadata["manip.capture"]["scenario"] == name
    (session,) = capture.sessions
    assert session.contact == "PUMA"
    assert all(pair.complete for pair in session.pairs.values())
    assert [e.event for e in session.events][:2] == ["rfc", "open"]


def test_golden_captures_hold_their_scenarios() -> None:
    describe = read_session(GOLDEN / "describe-self.mcap")
    multi = [p for p in describe.server_packets if p.op == "describe-self"]
    assert (
        len(multi) > 2
        and multi[-1].annotation.final
        and ":DEGREES-OF-FREEDOM" in "".join(p.annotation.text or "" for p in multi)
    )
    motion = read_session(GOLDEN / "motion.mcap")
    (segment,) = [p for p in motion.server_packets if p.kind == "async"]
    assert (
        segment.annotation.async_ is not None
        and segment.annotation.async_["condition_name"] == "segment-completed"
    )
    target = next(p for p in motion.requests if p.op == "set-joint-angles").annotation.fields
    final = [p for p in motion.server_packets if p.op == "joint-angles"][-1].annotation.fields
    assert target is not None and final is not None and final["joints"] == pytest.approx(target["joints"])
    errors = read_session(GOLDEN / "errors.mcap")
    codes = [p.annotation.error["code"] for p in errors.server_packets if p.annotation.error]
    assert codes == ["NAP", "UOP", "BDL", "BVA"]


@pytest.mark.parametrize("name", NAMES)
def test_golden_captures_are_deterministic_in_content(remade: Path, name: str) -> None:
    old, new = read_session(GOLDEN / f"{name}.mcap"), read_session(remade / f"{name}.mcap")
    assert new.exchange() == old.exchange()
    assert [(p.op, p.kind) for p in new.packets if p.kind != "control"] == [
        (p.op, p.kind) for p in old.packets if p.kind != "control"
    ]


def test_manip_decode_lists_a_capture() -> None:
    result = CliRunner().invoke(decode_main, ["--mcap", str(GOLDEN / "errors.mcap")])
    assert result.exit_code == 1, result.output  # the session sends malformed requests on purpose
    assert (
        "E NAP" in result.output
        and "manip error" in result.output
        and "request joint-angles" in result.output
    )
    assert "not a request opcode" in result.output
    result = CliRunner().invoke(decode_main, ["--mcap", str(GOLDEN / "motion.mcap"), "--format", "json"])
    assert result.exit_code == 0, result.output
    assert "segment-completed" in result.output and '"transform"' in result.output


def test_generated_capture_docs_are_current() -> None:
    module = load_tool("gen_capture_docs")
    current = (ROOT / "docs" / "captures.md").read_text()
    assert current == module.render(), "run: python tools/gen_capture_docs.py"


def test_info_json_gives_the_recorded_view_of_every_packet() -> None:
    path = GOLDEN / "motion.mcap"
    result = CliRunner().invoke(capture_main, ["info", str(path), "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    stored = {
        message.sequence: json.loads(message.data)
        for _, channel, message in make_reader(path.open("rb")).iter_messages()
        if channel.topic in ("/manip/c2s", "/manip/s2c")
    }
    assert (
        len(data["packets"]) == len(stored) == data["channels"]["/chaos/c2s"] + data["channels"]["/chaos/s2c"]
    )
    for packet in data["packets"]:  # the reader's annotation is the recorder's, field for field
        assert {k: v for k, v in packet.items() if k != "time_ns"} == stored[packet["seq"]]
    [session] = data["sessions"]
    assert session["answered"] == session["pairs"] and session["events"][-1]["event"] == "cls"
    assert data["metadata"]["manip.capture"]["tool"] == "manip"
