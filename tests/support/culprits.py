"""The promise that every violation names its culprit, checked on a run's JSON report.

A violation names the packets it judged (``judge/violation.py``), and the report keeps them whatever its
packet bound (``output/culprit.py``); only a violation about a packet that never came
(:data:`~manip.conformance.judge.violation.NEVER_CAME`) may name none.
"""

from __future__ import annotations

from manip.conformance.judge.violation import NEVER_CAME
from manip.conformance.output.report import report_json
from manip.conformance.suite.results import RunReport


def unnamed_violations(report: RunReport) -> list[str]:
    """The violations of ``report`` that name no packet, or whose packet the JSON report did not keep
    (those about a packet that never came excepted), each as ``case: [clause] message: why``."""
    out: list[str] = []
    for case in report_json(report)["cases"]:
        kept = {packet["n"] for packet in case["packets"]}
        for v in case["violations"]:
            if v["kind"] in NEVER_CAME:
                continue
            where = f"{case['id']}: [{v['clause']}] {v['message'][:120]}"
            if v["packet"] is None:
                out.append(f"{where}: names no packet")
            elif v["packet"] not in kept:
                out.append(f"{where}: its packet {v['packet']} was cut from the report")
    return out
