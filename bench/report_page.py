"""The HTML report of a long recording in a browser (run by hand): how soon the page is usable.

Workload: one embedded suite run recorded (``manip-conform run --seed 11 --record``, about 1,600 checks),
then ``manip-conform verify`` of that recording written as one HTML page.  The page's script notes when
it is done (``performance.now()``, in the page's ``data-ready-ms``): parsed to the end of its script and
the script run, Chromium's own start-up left out.

Baseline, measured in the same run and loaded alternately with the report: a page of the same size and
the same number of table rows, with no script, whose ready time is taken the same way.  The ratio is the
report's cost over what any page of its size costs this browser on this machine now, so load hits both
alike.

Target: usable within 2 s (median of the rounds), page under 2 MB.  The figures are printed
with a verdict; nothing is asserted (the machine is shared: run it twice).  The tests check the page's
size and that it becomes ready with every row; its speed is judged only here.

    .venv/bin/python bench/report_page.py [--rounds 5] [--chromium chromium]
"""

from __future__ import annotations

import argparse
import html
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

READY_TARGET_MS = 2000
PAGE_TARGET_BYTES = 2_000_000
_READY = re.compile(r'data-ready-ms="(\d+)"')


def _conform(*args: str, cwd: Path) -> None:
    command = [sys.executable, "-m", "manip.conformance.cli", *args]
    done = subprocess.run(command, cwd=cwd, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        said = done.stdout + done.stderr
        raise SystemExit(f"manip-conform {' '.join(args)} exited {done.returncode}:\n{said}")


def report_page(work: Path) -> Path:
    """The verify page of a whole suite run's recording."""
    _conform("run", "-q", "--seed", "11", "--record", "run.mcap", cwd=work)
    page = work / "verify.html"
    _conform("verify", "run.mcap", "--html", str(page), cwd=work)
    return page


def baseline_page(report: Path, work: Path) -> Path:
    """A page as large as ``report``, with as many table rows, and no script: what the browser costs."""
    text = report.read_text(encoding="utf-8")
    rows = text.count("<tr")
    filler = html.escape("x" * max(0, len(text) // max(rows, 1) - 40))
    body = "".join(f"<tr><td>{i}</td><td>{filler}</td></tr>" for i in range(rows))
    stamp = "document.documentElement.dataset.readyMs = String(Math.round(performance.now()));"
    page = work / "baseline.html"
    page.write_text(f"<!doctype html><html><body><table>{body}</table><script>{stamp}</script></body></html>")
    return page


def ready_ms(chromium: str, page: Path, profile: Path) -> int:
    """The page's own ready time in one headless load."""
    command = [chromium, "--headless=new", "--no-sandbox", "--disable-gpu", f"--user-data-dir={profile}"]
    command += ["--dump-dom", page.as_uri()]
    done = subprocess.run(command, capture_output=True, text=True, timeout=120, check=False)
    found = _READY.search(done.stdout)
    if done.returncode != 0 or not found:
        raise SystemExit(f"chromium gave no ready time for {page.name}: {done.stderr[-500:]}")
    return int(found.group(1))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--rounds", type=int, default=5, help="loads of each page, alternating (default 5)")
    parser.add_argument("--chromium", default="chromium", help="the browser to run headless")
    args = parser.parse_args(argv)
    chromium = shutil.which(args.chromium)
    if chromium is None:
        print(f"{args.chromium} is not installed (apt-get install chromium)", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        report = report_page(work)
        baseline = baseline_page(report, work)
        times: dict[str, list[int]] = {"report": [], "baseline": []}
        for _ in range(args.rounds):
            times["report"].append(ready_ms(chromium, report, work / "profile"))
            times["baseline"].append(ready_ms(chromium, baseline, work / "profile"))
        size = report.stat().st_size
    median = {name: statistics.median(values) for name, values in times.items()}
    ratio = median["report"] / max(median["baseline"], 1)
    small = "met" if size < PAGE_TARGET_BYTES else "MISSED"
    print(f"page: {size:,} bytes (target under {PAGE_TARGET_BYTES:,}: {small})")
    for name, values in times.items():
        print(f"{name}: median {median[name]:.0f} ms, min {min(values)} ms, max {max(values)} ms")
    met = "met" if median["report"] < READY_TARGET_MS else "MISSED"
    target = f"target under {READY_TARGET_MS} ms: {met}"
    print(f"ready: {median['report']:.0f} ms, {ratio:.2f}x the baseline ({target})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
