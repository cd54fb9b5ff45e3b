"""A release a stranger can install: ``python -m build`` makes an sdist and a wheel (the wheel built from
the sdist, as a user building from source does), ``twine check`` passes them, and the wheel installed in
a fresh virtual environment runs ``manip-conform run``, ``manip-decode`` and ``manip-client --version``.

No network: the build runs without isolation (hatchling is in the test extra), and the fresh
environment sees the dependencies already installed here through a path file that names a directory
holding every installed distribution but manip itself, so pip checks the wheel's requirements against
them (``--no-index``) and the only manip it can import is the wheel's.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import sysconfig
import tomllib
import zipfile
from pathlib import Path

import pytest

from tests.support.paths import ROOT

VERSION = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
RFC_PUMA = "01010000010000040120000001010a01000100005550414d012001015a1a"


def _run(
    *args: str | Path, cwd: Path | None = None, timeout: float = 300
) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    return subprocess.run(
        [str(a) for a in args], capture_output=True, text=True, timeout=300, check=False, cwd=cwd, env=env
    )


def _dependencies_only(where: Path) -> Path:
    """A directory of links to everything installed here except manip (its package, its editable
    finder, its metadata)."""
    site = Path(sysconfig.get_paths()["purelib"])
    deps = where / "deps"
    deps.mkdir()
    for entry in site.iterdir():
        if re.match(r"(_?_?editable__.*manip|_?manip)([.\-_].*)?$", entry.name, re.I):
            continue
        (deps / entry.name).symlink_to(entry)
    return deps


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_the_built_wheel_installs_and_runs_in_a_fresh_environment(tmp_path: Path) -> None:
    dist = tmp_path / "dist"
    built = _run(sys.executable, "-m", "build", "--no-isolation", "--outdir", dist, ROOT)
    assert built.returncode == 0, built.stdout[-3000:] + built.stderr[-3000:]
    wheel, sdist = dist / f"manip-{VERSION}-py3-none-any.whl", dist / f"manip-{VERSION}.tar.gz"
    assert wheel.exists() and sdist.exists(), sorted(p.name for p in dist.iterdir())
    checked = _run(sys.executable, "-m", "twine", "check", "--strict", wheel, sdist)
    assert checked.returncode == 0, checked.stdout + checked.stderr
    names = zipfile.ZipFile(wheel).namelist()
    for data in ("manip/spec/data/manip.toml", "manip/conformance/report.schema.json", "manip/py.typed"):
        assert data in names, data  # the spec data and assets ship in the wheel
    assert f"manip-{VERSION}.dist-info/licenses/LICENSE" in names  # the licence travels with the wheel

    env = tmp_path / "fresh"
    assert _run(sys.executable, "-m", "venv", env).returncode == 0
    purelib = "import sysconfig; print(sysconfig.get_paths()['purelib'])"
    fresh = Path(_run(env / "bin" / "python", "-c", purelib).stdout.strip())
    (fresh / "installed-dependencies.pth").write_text(f"{_dependencies_only(tmp_path)}\n")
    installed = _run(env / "bin" / "python", "-m", "pip", "install", "--no-index", "--no-cache-dir", wheel)
    assert installed.returncode == 0, installed.stdout[-3000:] + installed.stderr[-3000:]

    where = _run(env / "bin" / "python", "-c", "import manip, sys; print(manip.__file__)")
    assert where.stdout.strip().startswith(str(fresh)), where.stdout + where.stderr  # the wheel's, not src/
    version = _run(env / "bin" / "manip-client", "--version")
    assert version.returncode == 0 and version.stdout.strip() == f"manip-client, version {VERSION}"
    decoded = _run(env / "bin" / "manip-decode", RFC_PUMA)
    assert decoded.returncode == 0 and "contact 'PUMA'" in decoded.stdout, decoded.stdout + decoded.stderr
    conform = _run(
        env / "bin" / "manip-conform", "run", "--select", "server.reply.*", "--seed", "3", "--json", "r.json",
        cwd=tmp_path,
    )  # fmt: skip
    assert conform.returncode == 0, conform.stdout[-3000:] + conform.stderr[-3000:]
    assert "conformant (exit 0)" in conform.stdout and (tmp_path / "r.json").exists()


def test_the_example_ci_workflow_runs_the_suite_and_keeps_its_reports(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """docs/conformance-ci.yml: its manip-conform line parses (options renamed break this test, not an
    implementer's CI), writes the HTML, JUnit and Markdown reports, and the reports are kept always."""
    import shlex

    from manip.conformance.cli import main

    text = (ROOT / "docs" / "conformance-ci.yml").read_text()
    (line,) = [s.strip() for s in text.splitlines() if s.strip().startswith("manip-conform run")]
    words = shlex.split(line.replace('"$TARGET"', "tcp://127.0.0.1:42085"))
    for option in ("--html", "--junit", "--markdown"):
        assert option in words
    ran: list[dict[str, object]] = []
    run = main.commands["run"]  # type: ignore[attr-defined]
    monkeypatch.setattr(run, "callback", lambda **kwargs: ran.append(kwargs))
    main.main(words[1:], prog_name="manip-conform", standalone_mode=False)
    assert len(ran) == 1 and ran[0]["host"] == "tcp://127.0.0.1:42085"
    assert text.count("if: always()") >= 2 and "actions/upload-artifact" in text
    assert f'"manip=={VERSION.rsplit(".", 1)[0]}.*"' in text  # the version a user pins
