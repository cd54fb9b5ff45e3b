"""The Cougar target of manip-conform: the DRV-11J probe, the cases against the simulated Cougar, the
mutation proof (every Cougar fault caught), coverage of the cougar clauses, and the CLI."""

from __future__ import annotations

import asyncio
import itertools
import json
import socket
from collections.abc import Iterable
from pathlib import Path

import pytest
from click.testing import CliRunner

from manip.conformance.cli import main as conform_main
from manip.conformance.cougar.probe import CougarProbe, TickClock, cougar_liveness
from manip.conformance.cougar.target import CougarTarget, cougar_cases, run_cougar_suite, wait_idle
from manip.conformance.output.coverage import coverage, gaps
from manip.conformance.output.report import load_schema
from manip.conformance.output.report_view import packet_rows, wire_order
from manip.conformance.suite.case import CaseFailure, all_cases
from manip.conformance.suite.context import RunOptions
from manip.conformance.suite.results import ExitCode, RunReport
from manip.cougar import CougarConfig, CougarSim
from manip.cougar.cli import main as cougar_main
from manip.cougar.cli import serve_cougar
from manip.cougar.faults import CougarFault, parse_faults
from manip.cougar.link import CougarEnd, Drv11jError, PumaEnd, Tick, encode_frame
from manip.spec import SPEC
from tests.support.culprits import unnamed_violations
from tests.support.json_schema import validate
from tests.support.paths import ROOT
from tests.support.servers import MANIP_COUGAR, StartServer

#: The cases each fault declares catch it (others may catch it too): each must fail.
CATCHERS = {fault.value: fault.caught_by for fault in CougarFault}
OPTIONS = RunOptions(reply_timeout=1.0, connect_timeout=2.0)
MEMORY_MAP = ROOT / "examples" / "cougar-memory-map.toml"
"""manip's Cougar memory map as a file, declared for a manip-cougar process as for any external Cougar."""


def wanted(fault: CougarFault, case_id: str) -> set[str]:
    """The outcomes that count as catching ``fault`` in case ``case_id``: fail, or warn when every clause
    of the fault the case cites is a SHOULD (a SHOULD's violation warns)."""
    (case,) = (c for c in all_cases() if c.id == case_id)
    cited = set(case.clauses) & set(fault.clauses)
    return {"fail", "warn"} if cited and all(SPEC.clauses[c].level == "SHOULD" for c in cited) else {"fail"}


def run(target: CougarTarget, select: Iterable[str] = ()) -> RunReport:
    return asyncio.run(run_cougar_suite(target, seed=7, select=select, options=OPTIONS))


def outcomes(report: RunReport) -> dict[str, str]:
    return {r.id: r.outcome for r in report.results}


# ------------------------------------------------------------------------------------------ the suite
def test_clean_simulator_passes_every_cougar_case() -> None:
    report = run(CougarTarget.parse("sim"))
    expected = {c.id for c in cougar_cases(all_cases(), cougar=True)}
    assert set(outcomes(report)) == expected
    failed = {i: o for i, o in outcomes(report).items() if o != "pass"}
    assert not failed, [(r.id, r.violations, r.traceback) for r in report.results if r.outcome != "pass"]
    assert report.exit_code == ExitCode.CONFORMANT
    assert len(expected) >= 40


def test_every_fault_has_a_catching_case() -> None:
    assert set(CATCHERS) == {f.value for f in CougarFault}
    ids = {c.id for c in all_cases()}
    assert all(catchers and set(catchers) <= ids for catchers in CATCHERS.values())
    # every error path of the DRV-11J link (a case each) is declared caught by the fault that breaks it
    link_paths = {c.id for c in all_cases() if c.module.endswith(".link_errors")}
    declared = {
        case for fault, catchers in CATCHERS.items() if fault.startswith("link-") for case in catchers
    }
    assert link_paths <= declared, link_paths - declared


@pytest.mark.parametrize("fault", sorted(f.value for f in CougarFault))
def test_fault_is_caught(fault: str) -> None:
    report = run(CougarTarget.parse("sim", [fault]))
    got = outcomes(report)
    failed = [r for r in report.results if r.outcome == "fail"]
    shown = ", ".join(f"{r.id} ({r.violations[0].clause if r.violations else r.reason})" for r in failed)
    print(f"cougar fault {fault}: caught by {shown or 'NO CASE'}")
    switch = CougarFault.named(fault)
    assert all(got[case] in wanted(switch, case) for case in CATCHERS[fault]), (fault, got)
    assert report.exit_code == ExitCode.NON_CONFORMANT
    assert not any(o == "error" for o in got.values()), [r.traceback for r in report.results if r.traceback]
    declared = set(CougarFault.named(fault).clauses)
    for catcher in (r for r in report.results if r.id in CATCHERS[fault]):
        assert catcher.violations and all(v.clause for v in catcher.violations)
        assert {v.clause for v in catcher.violations} & declared, (fault, catcher.violations, declared)
        assert f"--cougar-fault {fault}" in catcher.reproduce
    assert not unnamed_violations(report), unnamed_violations(report)  # every culprit named and kept
    # every case passes on the clean simulator: a wrong answer fails, or leaves a case not judged naming
    # the case that judges it, and never makes one skip
    skipped = [(r.id, r.reason) for r in report.results if r.outcome == "skip"]
    assert not skipped, f"fault {fault} makes cases skip that pass on the clean Cougar: {skipped}"
    ids = {c.id for c in all_cases()}
    unnamed = [
        (r.id, r.reason)
        for r in report.results
        if r.outcome == "not-judged" and not any(i in r.reason for i in ids)
    ]
    assert not unnamed, f"fault {fault} leaves cases not judged naming nothing that judges them: {unnamed}"


@pytest.mark.waits
@pytest.mark.parametrize("fault", ["", *sorted(f.value for f in CougarFault)], ids=lambda f: f or "clean")
def test_fault_of_a_manip_cougar_process_is_caught_over_its_link(
    fault: str, manip_server: StartServer
) -> None:
    """A manip-cougar process with the fault (``--cougar-fault``), judged over its DRV-11J link as any
    external Cougar is (its memory map declared with the example file, ``--memory-map``), fails the cases
    that catch the fault in the embedded Cougar; the clean process passes every one of them."""
    selected = (
        sorted({c for catchers in CATCHERS.values() for c in catchers}) if not fault else CATCHERS[fault]
    )
    process = manip_server("--seed", "7", *(("--cougar-fault", fault) if fault else ()), command=MANIP_COUGAR)
    report = run(CougarTarget.parse(process.url, memory_map=MEMORY_MAP), select=selected)
    got = outcomes(report)
    assert set(got) == set(selected), got
    for r in report.results:
        want = wanted(CougarFault.named(fault), r.id) if fault else {"pass"}
        assert r.outcome in want, (r.id, r.outcome, r.reason, r.violations)


def test_every_must_cougar_clause_has_a_case() -> None:
    rows = coverage(all_cases(), {"cougar"})
    assert not gaps(rows), [r.clause for r in gaps(rows)]
    covered = {r.clause for r in rows if r.cases and r.party == "cougar"}
    assert {"cougar.rst", "cougar.guardc", "cougar.comint.unknown-code"} <= covered


def test_server_runs_leave_out_cougar_cases() -> None:
    cases = all_cases()
    server = cougar_cases(cases, cougar=False)
    cougar = cougar_cases(cases, cougar=True)
    assert server and cougar
    assert all(c.target == "server" for c in server)
    assert all(c.target == "cougar" and c.id.startswith("cougar.") for c in cougar)


def test_external_cougar_is_checked_over_its_url() -> None:
    async def scenario() -> RunReport:
        async with serve_cougar(CougarSim(seed=3), "tcp://127.0.0.1:0") as server:
            report = await run_cougar_suite(
                CougarTarget.parse(server.address),
                select=["cougar.reply.*", "cougar.guard.*"],
                options=OPTIONS,
            )
            await wait_idle(server)
            return report

    report = asyncio.run(scenario())
    assert report.results and all(r.outcome == "pass" for r in report.results)
    assert not report.embedded
    assert report.results[0].reproduce.startswith(f"manip-conform run --cougar {report.target} --select")


# ------------------------------------------------------------------------------------------ the probe
class SplitReplies:
    """A Cougar that holds back the last word of each tick's output until the next tick (a response
    split across ticks, as the framing allows)."""

    def __init__(self) -> None:
        self.sim = CougarSim(seed=1)
        self.held: list[int] = []

    def receive(self, words: Iterable[int]) -> None:
        self.sim.receive(words)

    def tick(self, now: float) -> list[int]:
        new = self.sim.tick(now)
        out = self.held + new[:-1]
        self.held = new[-1:]
        return out


def test_probe_reassembles_a_response_split_across_ticks() -> None:
    async def scenario() -> None:
        async with serve_cougar(SplitReplies(), "tcp://127.0.0.1:0") as server:
            probe = await CougarProbe.open(server.address, reply_timeout=1.0, connect_timeout=1.0)
            try:
                sent_at = probe.ticks
                reply = await probe.call("VERS", version=1)
                assert reply.name == "VERSION" and not reply.problem
                assert reply.tick == sent_at + 1  # the data word came one tick later
                assert len(reply.words) == 2
            finally:
                await probe.close()
                await wait_idle(server)

    asyncio.run(scenario())


def test_probe_reports_undecodable_responses_as_problems() -> None:
    class BadFloats:
        def receive(self, words: Iterable[int]) -> None:
            self.asked = list(words)

        def tick(self, now: float) -> list[int]:
            return [5, *([0x8000, 0] * 6)] if getattr(self, "asked", None) else []  # reserved operands

    async def scenario() -> None:
        async with serve_cougar(BadFloats(), "tcp://127.0.0.1:0") as server:
            probe = await CougarProbe.open(server.address, reply_timeout=1.0, connect_timeout=1.0)
            try:
                reply = await probe.call("RFRC")
                assert reply.message is None and reply.problem
                assert reply.code == 5
            finally:
                await probe.close()
                await wait_idle(server)

    asyncio.run(scenario())


def test_probe_waits_for_a_busy_cougar() -> None:
    async def scenario() -> None:
        async with serve_cougar(CougarSim(seed=1), "tcp://127.0.0.1:0") as server:
            first = await CougarProbe.open(server.address, reply_timeout=1.0, connect_timeout=1.0)
            second = asyncio.create_task(
                CougarProbe.open(server.address, reply_timeout=1.0, connect_timeout=1.0)
            )
            await asyncio.sleep(0.1)
            assert not second.done()  # refused as busy, retrying
            await first.close()
            probe = await asyncio.wait_for(second, 2.0)
            assert (await probe.call("VERS", version=1)).name == "VERSION"
            await probe.close()
            await wait_idle(server)

    asyncio.run(scenario())


def test_probe_times_out_on_a_cougar_that_never_ticks() -> None:
    async def scenario() -> None:
        server = await asyncio.start_server(_hello_then_silence, "127.0.0.1", 0)
        port = server.sockets[0].getsockname()[1]
        async with server:
            with pytest.raises(CaseFailure) as info:
                await CougarProbe.open(f"tcp://127.0.0.1:{port}", reply_timeout=0.2, connect_timeout=1.0)
            assert info.value.kind == "timeout" and info.value.clause == "link.drv11j.framing"

    asyncio.run(scenario())


async def _hello_then_silence(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    writer.write(CougarEnd(CougarSim()).hello())
    await reader.read(1 << 16)
    await asyncio.sleep(1.0)
    writer.close()


def test_liveness_of_nothing_listening() -> None:
    port = _free_port()
    alive, detail = asyncio.run(
        cougar_liveness(f"tcp://127.0.0.1:{port}", reply_timeout=0.2, connect_timeout=0.5)
    )
    assert not alive and "connect" in detail


def test_tick_clock_never_goes_back_and_honours_a_gap() -> None:
    clock = TickClock()
    times = [clock.next() for _ in range(50)]
    assert all(b - a >= clock.period - 1e-6 for a, b in itertools.pairwise(times))
    t = clock.next(gap=0.0005)
    assert t - times[-1] == pytest.approx(0.0005, abs=1e-6)
    assert clock.next() >= t + clock.period - 1e-6


# ------------------------------------------------------------------------------------------ Cougar side
def test_a_new_link_may_start_its_clock_anywhere() -> None:
    sim = CougarSim(seed=1)
    first = CougarEnd(sim)
    first.receive(PumaEnd().hello() + encode_frame(Tick(0, 1000.0)))
    second = CougarEnd(sim, resume_after=first.last_time)
    out = second.receive(PumaEnd().hello() + encode_frame(Tick(0, 5.0)) + encode_frame(Tick(1, 5.02)))
    assert second.ticks == 2 and out
    assert second.last_time is not None and second.last_time > 1000.0
    with pytest.raises(Drv11jError, match="backwards"):
        second.receive(encode_frame(Tick(2, 4.0)))


def test_faults_are_checked_names() -> None:
    assert parse_faults(["rst-ignored", " "]) == {"rst-ignored"}
    with pytest.raises(ValueError, match="unknown Cougar fault"):
        parse_faults(["no-such-fault"])
    with pytest.raises(ValueError):
        CougarConfig(faults=frozenset({"no-such-fault"}))
    assert CougarConfig(faults=frozenset({"rst-ignored"})).faults == {"rst-ignored"}
    with pytest.raises(ValueError, match="embedded"):
        CougarTarget.parse("tcp://127.0.0.1:1", ["rst-ignored"])
    with pytest.raises(ValueError):
        CougarTarget.parse("ftp://nowhere")


def test_manip_cougar_offers_the_faults() -> None:
    result = CliRunner().invoke(cougar_main, ["--help"])
    assert result.exit_code == 0 and "--cougar-fault" in result.output
    bad = CliRunner().invoke(cougar_main, ["--cougar-fault", "nope", "--listen", "tcp://127.0.0.1:0"])
    assert bad.exit_code == 2


# ------------------------------------------------------------------------------------------ the CLI
def test_cli_cougar_sim_report(tmp_path: Path) -> None:
    out = tmp_path / "report.json"
    result = CliRunner().invoke(
        conform_main,
        ["run", "--cougar", "--select", "cougar.reply.*", "-q", "--seed", "5", "--json", str(out)],
    )
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["cases"] and all(c["outcome"] == "pass" for c in data["cases"])
    assert all(c["id"].startswith("cougar.reply.") for c in data["cases"])


def test_cougar_report_shows_the_link_and_names_the_exchange(tmp_path: Path) -> None:
    """A Cougar case's report lists the words that went each way as DRV-11J records (commands sent,
    responses received; the schema's ``link``), and a violation names the response it judged, shown
    decoded in the report's view: a wrong VERSION code fails cougar.reply.version naming the response."""
    out = tmp_path / "report.json"
    CliRunner().invoke(
        conform_main,
        [
            *("run", "--cougar", "sim", "--cougar-fault", "wrong-version-code"),
            *("--select", "cougar.reply.version", "-q", "--seed", "5", "--json", str(out)),
        ],
    )
    data = json.loads(out.read_text())
    validate(data, load_schema(), load_schema())
    (case,) = data["cases"]
    assert case["outcome"] == "fail"
    assert {(p["dir"], p.get("link")) for p in case["packets"]} == {("c2s", "drv11j"), ("s2c", "drv11j")}
    rows = {row.number: row for row in packet_rows(case, wire_order(data))}
    culprits = [rows[v["packet"]] for v in case["violations"]]
    assert culprits and all("from Cougar" in row.head for row in culprits), culprits
    assert all(rows[row.number - 1].head.startswith("VERS 13 to Cougar") for row in culprits), rows


def test_cli_cougar_fault_is_non_conformant() -> None:
    result = CliRunner().invoke(
        conform_main,
        ["run", "--cougar", "sim", "--cougar-fault", "no-out-of-sync", "--select", "cougar.comint.*", "-q"],
    )
    assert result.exit_code == 1, result.output
    assert "cougar.comint.unknown-code" in result.output
    assert "--cougar-fault no-out-of-sync" in result.output  # the reproduce line


@pytest.mark.parametrize(
    "args",
    [
        ["run", "127.0.0.1:1", "--cougar", "sim"],
        ["run", "--cougar", "tcp://127.0.0.1:1", "--cougar-fault", "rst-ignored"],
        ["run", "--cougar", "sim", "--cougar-fault", "nope"],
        ["run", "--cougar", "ftp://nowhere"],
        ["run", "--cougar", "sim", "--server-fault", "x"],
    ],
)
def test_cli_cougar_usage_errors(args: list[str]) -> None:
    assert CliRunner().invoke(conform_main, args).exit_code == 2


def test_cli_unreachable_cougar() -> None:
    port = _free_port()
    result = CliRunner().invoke(
        conform_main, ["run", "--cougar", f"tcp://127.0.0.1:{port}", "--reply-timeout", "0.2", "-q"]
    )
    assert result.exit_code == 3, result.output


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
    return port
