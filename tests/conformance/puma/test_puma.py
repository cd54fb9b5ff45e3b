"""The Puma target of manip-conform (``run --puma``): the judging Cougar, the puma cases against the
reference server (clean: all pass; each wrist-side fault switch: caught by its named case), the same over
TCP in real time, coverage of the puma clauses, and the CLI."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from manip.codecs.cougar import OutOfSync, encode
from manip.conformance.cli import main as conform_main
from manip.conformance.output.coverage import DEFAULT_PARTIES, coverage, gaps
from manip.conformance.puma.judge import (
    CougarScript,
    FramedPort,
    JudgingCougar,
    NoJudgeError,
    current_judge,
    judging,
)
from manip.conformance.puma.target import PumaTarget, puma_cases, run_puma_suite
from manip.conformance.suite.case import all_cases
from manip.conformance.suite.context import RunOptions
from manip.conformance.suite.results import ExitCode, RunReport
from manip.conformance.suite.runner import RunConfig, Runner
from manip.conformance.suite.world_link import open_world
from manip.cougar.cli import serve_cougar
from manip.links import virtual_clock
from manip.reference_server.faults import WRIST_SIDE, Fault
from manip.spec import SPEC
from tests.support.culprits import unnamed_violations
from tests.support.servers import StartServer

SEED = 5
#: The cases each wrist-side fault declares catch it (others may catch it too).
CATCHERS: dict[Fault, tuple[str, ...]] = {fault: fault.caught_by for fault in WRIST_SIDE}


def run(target: PumaTarget, select: tuple[str, ...] = ()) -> RunReport:
    return virtual_clock.run(
        run_puma_suite(target, seed=SEED, select=select, options=RunOptions(reply_timeout=1.0)),
        virtual=target.virtual and target.embedded,
    )


def outcomes(report: RunReport) -> dict[str, str]:
    return {r.id: r.outcome for r in report.results}


# ------------------------------------------------------------------------------------------ the judge
def test_judge_records_commands_by_tick_and_scripts_answers() -> None:
    judge = JudgingCougar(seed=1)
    port = FramedPort(judge)
    judge.begin(CougarScript(forces=(1.0, 2.0, 3.0, 4.0, 5.0, 6.0), forces_delay=2))
    port.send(encode("command", "SEN", theta_sensed=(0.0, -90.0, 90.0, 0.0, 0.0, 0.0)))
    port.send(encode("command", "RFRC"))
    port.tick(1.0)
    assert [h.msg.name for h in judge.heard if h.msg] == ["SEN", "RFRC"]
    assert all(h.tick == 0 for h in judge.heard)
    assert judge.pose == (0.0, -90.0, 90.0, 0.0, 0.0, 0.0)
    assert port.receive() == []  # held back two ticks
    port.tick(1.016)
    port.tick(1.032)
    words = port.receive()
    assert words == encode("response", "FORCES", forces=(1.0, 2.0, 3.0, 4.0, 5.0, 6.0))
    assert [(s.tick, s.msg.name) for s in judge.said] == [(2, "FORCES")]
    judge.inject("GUARD-STOP", after=1, index=3)
    port.tick(1.048)
    assert port.receive() == []
    port.tick(1.064)
    assert port.receive() == encode("response", "GUARD-STOP", index=3)


def test_judge_keeps_guards_from_its_simulator_and_reports_unreadable_words() -> None:
    judge = JudgingCougar(seed=1)
    port = FramedPort(judge)
    port.send(encode("command", "GUARDS", type_index=0x8002, dvec=(0.0,) * 6, tol=-1.0))  # trips at once
    for k in range(5):
        port.tick(1.0 + k * 0.016)
    assert port.receive() == []  # the simulator never saw the guard
    port.send([0o777, 1, 2])
    assert isinstance(judge.heard[-1].item, OutOfSync)


def test_cases_need_a_judge() -> None:
    with pytest.raises(NoJudgeError):
        current_judge()


# ------------------------------------------------------------------------------------------ the suite
def test_clean_reference_server_passes_every_puma_case() -> None:
    report = run(PumaTarget())
    expected = {c.id for c in puma_cases(all_cases())}
    assert set(outcomes(report)) == expected
    assert len(expected) >= 10
    bad = [(r.id, r.outcome, r.violations, r.reason) for r in report.results if r.outcome != "pass"]
    assert not bad, bad
    assert report.exit_code == ExitCode.CONFORMANT
    assert report.time == "virtual"


def test_every_wrist_side_fault_has_a_catcher() -> None:
    assert set(CATCHERS) == set(WRIST_SIDE)
    cases = {c.id: c for c in all_cases()}
    for fault, catchers in CATCHERS.items():
        assert catchers, fault
        assert all(set(fault.clauses) & set(cases[case_id].clauses) for case_id in catchers), fault


@pytest.mark.parametrize("fault", sorted(CATCHERS, key=lambda f: f.value), ids=lambda f: f.value)
def test_wrist_side_fault_is_caught_by_its_case(fault: Fault) -> None:
    report = run(PumaTarget(faults=(fault.value,)))
    got = outcomes(report)
    errors = [(r.id, r.traceback) for r in report.results if r.outcome == "error"]
    assert not errors, errors
    assert not unnamed_violations(report), unnamed_violations(report)  # every culprit named and kept
    must = any(SPEC.clauses[c].level == "MUST" for c in fault.clauses)  # a SHOULD clause warns
    assert {got[case] for case in CATCHERS[fault]} == {"fail" if must else "warn"}, got
    if must:
        assert report.exit_code == ExitCode.NON_CONFORMANT
    # every case passes on the clean server: a wrong answer never makes one skip or leaves it not judged
    unjudged = [(r.id, r.outcome, r.reason) for r in report.results if r.outcome in ("skip", "not-judged")]
    assert not unjudged, f"fault {fault.value} leaves cases unjudged that pass when clean: {unjudged}"


PROCESS_FAULTS = (
    Fault.WRIST_CONFIG_AFTER_MOTION,
    Fault.WRIST_USER_HELD_COMPLIANT,
    Fault.OUT_OF_SYNC_IGNORED,
    Fault.GUARDS_OUTLIVE_CONNECTION,
    Fault.COMPLIANT_NOMINAL_IGNORED,
    Fault.WRIST_USER_BEFORE_MOVE_QUEUE,
)
"""The Puma's wrist defects found from outside (a setting held back while the arm moves, the user's
requests held during a compliant segment, Cougar's out-of-sync message dropped, guards left armed for
the next connection, a compliant segment off its nominal path, the user's commands ahead of the move
process's), each caught through a manip-server process with its world, as the suite judges a Puma at
HOST."""


def _catching(fault: Fault | None) -> set[str]:
    """The cases ``fault`` declares catch it; for None, those of every fault in :data:`PROCESS_FAULTS`."""
    return {c for f in PROCESS_FAULTS for c in CATCHERS[f]} if fault is None else set(CATCHERS[fault])


PROCESS_TIME_SCALE = 0.5
"""The server process runs at half speed (``--time-scale``, and the run is told so): a compliant segment
lasts long enough in real time for a busy machine's suite to reach it while it runs."""


async def _judge_a_server_process(manip_server: StartServer, fault: Fault | None) -> RunReport:
    """The judging Cougar on a free port, a manip-server process (``--cougar`` pointed at it, its world
    on another port, ``--fault`` if one), and the case catching ``fault`` (all of them when None) run
    against it with its world."""
    wanted = _catching(fault)
    selected = [c for c in puma_cases(all_cases()) if c.id in wanted]
    judge = JudgingCougar(SEED)
    with judging(judge):
        async with serve_cougar(judge, "tcp://127.0.0.1:0") as cougar:
            args = ("--cougar", cougar.address, "--world", "tcp://127.0.0.1:0", "--log-level", "WARNING")
            args += ("--time-scale", str(PROCESS_TIME_SCALE))
            extra = ("--fault", fault.value) if fault is not None else ()
            process = await asyncio.to_thread(manip_server, *args, *extra)
            assert process.proc.stdout is not None
            line = await asyncio.to_thread(process.proc.stdout.readline)
            assert "world on" in line, line
            world_url = line.split("world on ", 1)[1].split()[0]
            async with asyncio.timeout(20.0):
                while not cougar.connections:
                    await asyncio.sleep(0.01)
            async with open_world(world_url) as world:
                options = RunOptions(address=process.url, reply_timeout=2.0, time_scale=PROCESS_TIME_SCALE)
                config = RunConfig(options=options, seed=SEED, world=world)
                return await Runner(config, selected).run()


@pytest.mark.waits
@pytest.mark.parametrize("fault", [None, *PROCESS_FAULTS], ids=lambda f: f.value if f else "clean")
def test_wrist_defect_of_a_server_process_is_caught_through_its_world(
    fault: Fault | None, manip_server: StartServer
) -> None:
    """A manip-server process whose wrist is the judging Cougar, run with its world: each defect fails
    (or warns, for a SHOULD clause) the case that catches it in the embedded server, and the clean process
    passes those cases."""
    report = asyncio.run(_judge_a_server_process(manip_server, fault))
    got = outcomes(report)
    shown = [(r.id, r.outcome, r.reason, [v.message for v in r.violations]) for r in report.results]
    if fault is None:
        assert got == dict.fromkeys(_catching(None), "pass"), shown
        return
    must = any(SPEC.clauses[c].level == "MUST" for c in fault.clauses)  # a SHOULD clause warns
    assert got == dict.fromkeys(_catching(fault), "fail" if must else "warn"), shown


@pytest.mark.slow
def test_real_time_over_tcp_passes_and_catches_a_fault() -> None:
    """The judge on a tcp:// port, the reference server on its own thread with --cougar pointed at it.

    The clean run leaves the compliance cases out: they hold the Puma to its 16 ms servo, which a heavily
    loaded test machine cannot keep in wall-clock time (virtual time holds them, above).  A fault that
    halves the New Position and Rate commands is still caught in real time."""
    clean = run(PumaTarget(virtual=False), select=("puma.wrist.*", "puma.guard.*", "puma.calibrate-wrist"))
    assert {r.outcome for r in clean.results} == {"pass"}, [(r.id, r.violations) for r in clean.results]
    faulty = run(
        PumaTarget(virtual=False, faults=("guard-ignored", "npr-skipped")),
        select=("puma.guard.*", "puma.compliance.npr-every-cycle"),
    )
    assert outcomes(faulty)["puma.guard.stop"] == "fail"
    assert outcomes(faulty)["puma.compliance.npr-every-cycle"] == "fail"  # half the NPRs, even late


def test_external_puma_that_never_links_is_unreachable() -> None:
    result = CliRunner().invoke(
        conform_main,
        ["run", "--puma", "tcp://127.0.0.1:9", "--wrist-listen", "tcp://127.0.0.1:0", "--wrist-wait", "0.3"],
    )
    assert result.exit_code == ExitCode.UNREACHABLE, result.output
    assert "no wrist link" in result.output


# ------------------------------------------------------------------------------------------ coverage
def test_default_coverage_includes_puma_with_no_gap() -> None:
    assert "puma" in DEFAULT_PARTIES
    rows = coverage(all_cases())
    puma = [r for r in rows if r.party == "puma"]
    assert puma and all(r.in_scope for r in puma)
    assert not gaps(rows), [r.clause for r in gaps(rows)]
    must = {cid for cid, c in SPEC.clauses.items() if c.party == "puma" and c.level == "MUST"}
    covered = {c for case in puma_cases(all_cases()) for c in case.clauses}
    assert must <= covered


# ------------------------------------------------------------------------------------------ the CLI
def test_cli_run_puma_json(tmp_path: Path) -> None:
    out = tmp_path / "report.json"
    result = CliRunner().invoke(conform_main, ["run", "--puma", "--seed", "3", "-q", "--json", str(out)])
    assert result.exit_code == 0, result.output
    report = json.loads(out.read_text())
    assert {c["target"] for c in report["cases"]} == {"puma"}
    assert len(report["cases"]) == len(puma_cases(all_cases()))


def test_cli_run_puma_with_a_fault_fails_and_names_the_clause() -> None:
    result = CliRunner().invoke(
        conform_main, ["run", "--puma", "--seed", "3", "-q", "--server-fault", "guard-unreported"]
    )
    assert result.exit_code == 1, result.output
    assert "puma.guard.report" in result.output


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--puma", "--cougar", "sim"], "not both"),
        (["--puma", "--wrist-listen", "tcp://127.0.0.1:1"], "--puma HOST"),
        (["--wrist-wait", "3"], "apply to --puma"),
        (["--puma", "tcp://127.0.0.1:1", "--wrist-listen", "udp://x"], "--puma"),
        (["--puma", "--server-fault", "no-such"], "unknown fault"),
    ],
)
def test_cli_usage_errors(args: list[str], message: str) -> None:
    result = CliRunner().invoke(conform_main, ["run", *args])
    assert result.exit_code == 2, result.output
    assert message in result.output


def test_repeat_gives_stable_verdicts() -> None:
    result = CliRunner().invoke(conform_main, ["run", "--puma", "--seed", "11", "--repeat", "3"])
    assert result.exit_code == 0, result.output
    assert "0 stability problem(s)" in result.output
