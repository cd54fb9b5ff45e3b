"""``manip-client``: every command against the reference server (in a thread of the test), the error
lines and exit statuses, and ``watch`` against a scripted server."""

from __future__ import annotations

import json

import pytest

from manip.arm.kinematics import PUMA600, forward
from manip.arm.transform import Transform
from manip.reference_client.cli import (
    EXIT_CONNECTION,
    EXIT_SERVER_ERROR,
    EXIT_TIMEOUT,
    EXIT_USAGE,
)
from tests.support.client_cli import invoke, watch_until_ctrl_c
from tests.support.scripted import READY, TARGET, never_answers, segment_reporter
from tests.support.servers import free_port, in_thread, scripted_server


def ok(*args: str) -> str:
    result = invoke(*args)
    assert result.exit_code == 0, (result.exit_code, result.output)
    assert result.stderr == ""
    return result.stdout


def ok_json(*args: str) -> dict[str, object]:
    out = ok(*args, "--json")
    value = json.loads(out)
    assert isinstance(value, dict)
    return value


def failed(code: int, *args: str) -> str:
    """The one stderr line of a failure with exit status ``code``."""
    result = invoke(*args)
    assert result.exit_code == code, (result.exit_code, result.output)
    lines = result.stderr.splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith("manip-client: ")
    return lines[0]


# ------------------------------------------------------------------ commands


def test_describe(url: str) -> None:
    text = ok(url, "describe")
    assert "degrees-of-freedom  6" in text
    assert "0200 0201 0202" in text  # opcodes in octal
    record = ok_json(url, "describe")
    assert record["degrees-of-freedom"] == 6


def test_here_text_and_json(url: str) -> None:
    ok(url, "move-joints", *map(str, READY), "--power", "--wait")
    text = ok(url, "here")
    lines = dict(line.split(None, 1) for line in text.splitlines()[:6])
    assert set(lines) == {"x", "y", "z", "O", "A", "T"}
    assert lines["x"].endswith("mm") and lines["O"].endswith("deg")
    record = ok_json(url, "here")
    floats = record["transform"]
    assert isinstance(floats, list)
    assert Transform.from_floats(floats).almost_equal(forward(READY, PUMA600.geometry), 1e-2)
    assert float(lines["z"].split()[0]) == pytest.approx(record["xyzoat"]["z"], abs=1e-3)  # type: ignore[index]


def test_move_joints_waits_then_joints_reports_them(url: str) -> None:
    assert ok(url, "move-joints", *map(str, TARGET), "--power", "--wait").startswith("segment ")
    assert ok_json(url, "joints")["joints"] == pytest.approx(TARGET, abs=1e-3)
    text = ok(url, "joints")
    assert text.splitlines()[1].split() == ["joint", "2", f"{TARGET[1]:.3f}", "deg"]
    record = ok_json(url, "ready", "--power", "--wait")
    assert record["completed"] is True
    assert ok_json(url, "--json", "joints")["joints"] == pytest.approx(READY, abs=1e-3)


def test_motion_without_power_is_a_protocol_error(url: str) -> None:
    line = failed(EXIT_SERVER_ERROR, url, "ready")
    assert line.startswith("manip-client: NAP: No arm power (ready: E NAP")


def test_power_and_speed(url: str) -> None:
    assert ok(url, "power", "on") == "arm power on\n"
    assert ok_json(url, "power", "off") == {"power": "off"}
    assert ok(url, "speed", "0.5") == "speed factor 0.5\n"
    assert "speed factor" in failed(EXIT_USAGE, url, "speed", "1.5")
    assert invoke(url, "power", "sideways").exit_code == EXIT_USAGE


def test_solve_backwards_then_forwards(url: str) -> None:
    pose = ok_json(url, "solve-backwards", *map(str, TARGET))
    floats = pose["transform"]
    assert isinstance(floats, list)
    assert Transform.from_floats(floats).almost_equal(forward(TARGET, PUMA600.geometry), 1e-2)
    current = ["--current", *map(str, TARGET)]
    by_transform = ok_json(url, "solve-forwards", *map(str, floats), *current)
    assert by_transform["joints"] == pytest.approx(TARGET, abs=1e-2)
    xyzoat = pose["xyzoat"]
    assert isinstance(xyzoat, dict)
    six = [str(xyzoat[k]) for k in ("x", "y", "z", "o", "a", "t")]
    assert ok_json(url, "solve-forwards", *six, *current)["joints"] == pytest.approx(TARGET, abs=1e-2)
    assert invoke(url, "solve-forwards", "1", "2", "3").exit_code == EXIT_USAGE


# ------------------------------------------------------------------ failures and watch


def test_cannot_connect() -> None:
    line = failed(EXIT_CONNECTION, f"tcp://127.0.0.1:{free_port()}", "here", "--timeout", "2")
    assert "cannot connect to tcp://127.0.0.1:" in line


def test_bad_url_is_a_usage_error() -> None:
    assert "unknown link scheme" in failed(EXIT_USAGE, "http://example.invalid", "here")


def test_no_reply_in_time() -> None:
    with in_thread(scripted_server(never_answers)) as address:
        line = failed(EXIT_TIMEOUT, address, "--timeout", "0.2", "here")
    assert "no reply within 0.2 s" in line


def test_watch_prints_asynchronous_responses() -> None:
    with in_thread(scripted_server(segment_reporter)) as address:
        result = invoke(address, "watch", "--count", "2")
        assert result.stdout == "segment 7 completed\nsegment 8 completed\n"
        assert result.stderr.startswith("manip-client: waiting for segment completions")  # said, not output
        lines = invoke(address, "watch", "--count", "1", "--json").stdout.splitlines()
        assert [json.loads(line)["segment"] for line in lines] == [7]
        assert invoke(address, "watch", "--seconds", "0").stdout == ""


def test_watch_stops_cleanly_on_ctrl_c() -> None:
    watch_until_ctrl_c()
