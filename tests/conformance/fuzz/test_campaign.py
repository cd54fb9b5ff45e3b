"""``manip-conform fuzz`` against real targets: the campaign as evidence, and the fuzzer's own proof.

* The reference server takes tens of thousands of inputs (and a CHUDP campaign) with no crash, hang,
  traceback or any other violation.
* Each kind of defect is found, shrunk to the one input that causes it, and its reproduce line
  causes it again: a crash, a hang, a traceback and a silent drop (``tests/support/fuzz_fake_server.py``,
  started by the fuzzer with ``--launch``), and a protocol fault switch of the reference server
  (which the same inputs do not trip without the fault).
* A campaign's report is the suite's report (``report.schema.json``) with its ``campaign`` block; usage
  errors exit 2, an unreachable target 3.
"""

from __future__ import annotations

import json
import shlex
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner, Result

from manip.conformance.cli import main
from manip.conformance.fuzz.generators import GenOptions, generate
from manip.conformance.fuzz.steps import RequestStep
from manip.conformance.judge.violation import FAILURE_KINDS
from manip.conformance.output.report import load_schema
from tests.support.json_schema import validate as _validate
from tests.support.paths import SUPPORT
from tests.support.servers import StartServer, free_port

FAKE = SUPPORT / "fuzz_fake_server.py"
TRIGGER = 0o277
KINDS = ("crash", "timeout", "traceback", "missing_response", "wrong_value", "uncounted_drop")


def fuzz(*args: str) -> Result:
    return CliRunner().invoke(main, ["fuzz", *args], catch_exceptions=False)


def report_of(path: Path) -> dict[str, Any]:
    """The campaign's JSON report, valid for the suite's report schema, each of its violations one as the
    report's cases have it with the suite's kinds; returned with its ``campaign`` block's fields on top
    (the campaign's ``counts`` are its violations by kind, the report's its cases by outcome)."""
    data: dict[str, Any] = json.loads(path.read_text())
    schema = load_schema()
    _validate(data, schema, schema)
    shape = schema["$defs"]["violation"]
    campaign = data["campaign"]
    for violation in campaign["violations"]:
        _validate({key: violation[key] for key in shape["required"]}, shape, schema)
        assert violation["kind"] in FAILURE_KINDS
        case = next(c for c in data["cases"] if c["id"] == violation["input_class"])
        assert violation["message"] in [v["message"] for v in case["violations"]]
    return {**data, **campaign}


def assert_clean(report: dict[str, Any], inputs: int) -> None:
    assert report["exit_code"] == 0, [f["message"] for f in report["violations"]]
    assert report["inputs"] == inputs
    assert report["counts"] == dict.fromkeys(KINDS, 0)
    assert report["violations"] == [] and report["warnings"] == 0
    assert report["tracebacks_seen"] == 0, "the fuzzer read the server's log and found tracebacks"
    assert report["liveness"]["failed"] == 0 and report["liveness"]["checks"] == report["batches"]
    assert report["bad_frames"]["counted"] == report["bad_frames"]["sent"] > 0
    assert all(c["inputs"] > 0 for c in report["classes"]), "every class was sent"


# ------------------------------------------------------------------------------------------ evidence


@pytest.mark.waits
@pytest.mark.timeout(150)
def test_a_short_campaign_against_the_reference_server_finds_nothing(tmp_path: Path) -> None:
    """Thousands of inputs (about ten seconds here; the long campaigns are ``fuzz``'s own, by hand): no
    crash, hang, traceback, drop."""
    path = tmp_path / "fuzz.json"
    result = fuzz("--inputs", "6000", "--seed", "20161", "--batch", "200", "--json", str(path))
    report = report_of(path)
    assert_clean(report, 6000)
    assert report["requests"] > 12000
    assert result.exit_code == 0, result.output
    assert "6000 inputs" in result.output and "conformant (exit 0)" in result.output
    print(f"fuzz campaign: {report['inputs']} inputs in {report['duration']:.1f} s ({report['rate']:.0f}/s)")


@pytest.mark.waits
@pytest.mark.timeout(90)
def test_a_chudp_campaign_against_the_reference_server_finds_nothing(tmp_path: Path) -> None:
    path = tmp_path / "fuzz.json"
    result = fuzz("--link", "chudp", "--inputs", "5000", "--seed", "3", "--json", str(path))
    report = report_of(path)
    assert_clean(report, 5000)
    assert {c["id"] for c in report["classes"]} >= {"link.chudp-header", "chaos.oversize"}
    assert result.exit_code == 0


# ------------------------------------------------------------------------------------------ defects


def first_trigger(seed: int, options: GenOptions) -> int:
    """The first input of the campaign that sends opcode 0277 (the fake server's trigger)."""
    for number in range(5000):
        item = generate(seed, number, options)
        if any(isinstance(s, RequestStep) and s.opcode == TRIGGER for s in item.steps):
            return number
    raise AssertionError("no input sends the trigger")


def reproduce(line: str, tmp_path: Path) -> dict[str, Any]:
    words = shlex.split(line)
    assert words[:2] == ["manip-conform", "fuzz"] and "--only" in words
    path = tmp_path / "again.json"
    fuzz(*words[2:], "--json", str(path), "-q")
    return report_of(path)


@pytest.mark.waits
@pytest.mark.timeout(120)
@pytest.mark.parametrize(
    ("mode", "kind"),
    [("crash", "crash"), ("hang", "timeout"), ("traceback", "traceback"), ("drop", "missing_response")],
)
def test_a_defect_is_found_shrunk_to_its_input_and_reproduced(mode: str, kind: str, tmp_path: Path) -> None:
    seed = 5
    classes = ("manip.unknown-opcode",)
    trigger = first_trigger(seed, GenOptions(select=classes))
    port = free_port()  # the fuzzer launches, and relaunches, the server itself: a fixed port
    url = f"tcp://127.0.0.1:{port}"
    launch = shlex.join([sys.executable, str(FAKE), mode, "--listen", url, "--log-level", "WARNING"])
    path = tmp_path / "fuzz.json"
    args = ["--class", classes[0], "--launch", launch, "--reply-timeout", "0.5", "--connect-timeout", "1"]
    result = fuzz(
        url, *args, "--seed", str(seed), "--inputs", str(trigger + 20), "--batch", "50", "--json", str(path)
    )
    report = report_of(path)
    assert result.exit_code == 1, result.output
    found = [f for f in report["violations"] if f["kind"] == kind]
    assert found, [(f["kind"], f["message"]) for f in report["violations"]]
    violation = found[0]
    assert violation["shrunk"] and [m["number"] for m in violation["minimal"]] == [trigger]
    assert "request 0277" in violation["minimal"][0]["steps"][0]
    assert f"--only {trigger}" in violation["reproduce"] and "--launch" in violation["reproduce"]
    assert violation["input_class"] == "manip.unknown-opcode"
    if kind in ("crash", "timeout"):
        assert report["restarts"] >= 1
    again = reproduce(violation["reproduce"], tmp_path)
    assert again["exit_code"] == 1 and any(f["kind"] == kind for f in again["violations"])


@pytest.mark.timeout(90)
def test_a_traceback_in_the_log_of_a_server_run_elsewhere_is_found(
    tmp_path: Path, manip_server: StartServer
) -> None:
    seed = 5
    trigger = first_trigger(seed, GenOptions(select=("manip.unknown-opcode",)))
    log = tmp_path / "server.log"
    with log.open("w") as stderr:  # a process on purpose: a defective server, its log in a file
        server = manip_server(
            "--log-level", "WARNING", command=[sys.executable, str(FAKE), "traceback"], stderr=stderr
        )
    assert server.line.startswith("manip-server: listening")
    url = server.url
    path = tmp_path / "fuzz.json"
    args = ["--class", "manip.unknown-opcode", "--server-log", str(log), "--seed", str(seed)]
    result = fuzz(url, *args, "--inputs", str(trigger + 20), "--batch", "50", "--json", str(path))
    report = report_of(path)
    assert result.exit_code == 1, result.output
    (violation,) = report["violations"]
    assert violation["kind"] == "traceback" and "fake defect" in violation["actual"]
    assert [m["number"] for m in violation["minimal"]] == [trigger]
    assert f"--server-log {log}" in violation["reproduce"]
    assert report["tracebacks_seen"] >= 1


@pytest.mark.timeout(90)
def test_a_fault_switch_is_found_and_its_reproduce_line_needs_the_fault(tmp_path: Path) -> None:
    path = tmp_path / "fuzz.json"
    junit = tmp_path / "fuzz.xml"
    result = fuzz(
        "--server-fault",
        "length-unchecked",
        "--inputs",
        "500",
        "--seed",
        "1",
        "--json",
        str(path),
        "--junit",
        str(junit),
    )
    report = report_of(path)
    assert result.exit_code == 1
    (violation,) = [f for f in report["violations"] if f["clause"] == "request.data-length"]
    assert violation["kind"] == "wrong_value" and violation["counts"] and violation["level"] == "MUST"
    assert violation["shrunk"] and len(violation["minimal"]) == 1
    assert violation["spec"].startswith("A request whose data length does not fit")
    assert "--server-fault length-unchecked" in violation["reproduce"]
    again = reproduce(violation["reproduce"], tmp_path)
    assert any(f["clause"] == "request.data-length" for f in again["violations"])
    without = reproduce(violation["reproduce"].replace(" --server-fault length-unchecked", ""), tmp_path)
    assert without["exit_code"] == 0, "the same input finds nothing without the fault"
    tree = ET.parse(junit)
    classes = [s for s in tree.iter("testsuite") if s.get("name") != "clauses"]  # not the clause statuses
    failed = [
        case.get("name") for s in classes for case in s.iter("testcase") if case.find("failure") is not None
    ]
    assert failed == [violation["input_class"]]
    assert "inputs (" in result.output and "reproduce: manip-conform fuzz --seed 1 --only" in result.output


# ------------------------------------------------------------------------------------------ usage


@pytest.mark.parametrize(
    "args",
    [
        ["tcp://127.0.0.1:1", "--server-fault", "wrong-severity"],
        ["tcp://127.0.0.1:1", "--wrist"],
        ["--launch", "true"],
        ["--server-log", "x.log"],
        ["--allow-motion"],
        ["--class", "manip.nothing-like-it"],
        ["--only", "1,2", "--inputs", "5"],
        ["--only", "one"],
        ["--server-fault", "no-such-fault"],
        ["chaosd:///tmp/chaosd"],
    ],
)
def test_usage_errors_exit_2(args: list[str]) -> None:
    result = fuzz(*args)
    assert result.exit_code == 2, result.output


def test_an_unreachable_target_exits_3(tmp_path: Path) -> None:
    path = tmp_path / "fuzz.json"
    result = fuzz(f"tcp://127.0.0.1:{free_port()}", "--connect-timeout", "0.3", "--json", str(path))
    assert result.exit_code == 3, result.output
    report = report_of(path)
    assert report["verdict"] == "target unreachable" and report["inputs"] == 0
    assert "not alive" in report["problems"][0]


def test_the_class_list_names_what_the_spec_expects() -> None:
    result = fuzz("--list-classes")
    assert result.exit_code == 0
    assert "manip.wrong-length  [MUST" in result.output and "C BDL" in result.output
    assert result.output.count("expected:") >= 25
