"""manip-conform: the conformance suite for Chaos manipulator servers and Cougar wrist computers.

The package, in the order a run goes through it (``docs/architecture.md`` tells the whole story):

* :mod:`~manip.conformance.suite`: declaring cases (``case``), what a case works with (``context``:
  ``CaseContext``, ``Probe``), running them (``runner``, ``selection``; in virtual time ``embedded`` and
  ``bridge``), their outcomes (``results``) and the suite invariants (``invariants``);
* :mod:`~manip.conformance.judge`: the one violation record, the pure checkers and the stateful model
  (no I/O; reused offline by ``verify`` and replay);
* :mod:`~manip.conformance.cases`: the cases, ``cases.server`` and ``cases.cougar`` by the id's target;
* :mod:`~manip.conformance.cougar`: the Cougar target (its word-level probe over the DRV-11J);
* :mod:`~manip.conformance.replay`: replay against a server, serving a recording, ``verify``, masking;
* :mod:`~manip.conformance.output`: console, packet text, JSON/JUnit reports, coverage;
* :mod:`~manip.conformance.cli`: the ``manip-conform`` command.

Modules that moved keep their old import path (``manip.conformance.checks`` is
``manip.conformance.judge.checks``, the same module object): :data:`MOVED` lists them.  The old paths
are deprecated; new code imports the new ones.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
from collections.abc import Sequence
from types import ModuleType
from typing import Final

MOVED: Final[dict[str, str]] = {
    "case": "suite.case",
    "context": "suite.context",
    "runner": "suite.runner",
    "selection": "suite.selection",
    "results": "suite.results",
    "invariants": "suite.invariants",
    "embedded": "suite.embedded",
    "bridge": "suite.bridge",
    "stability": "suite.stability",
    "strategies": "suite.strategies",
    "rawchaos": "suite.rawchaos",
    "report": "output.report",
    "coverage": "output.coverage",
    "console": "output.console",
    "packet_text": "output.packet_text",
    "checks": "judge.checks",
    "model": "judge.model",
    "replay_serve": "replay.serve",
    "replay_cli": "replay.cli",
    "verify": "replay.verify",
    "masking": "replay.masking",
    "capture_report": "replay.capture_report",
    "cougar_probe": "cougar.probe",
    "cougar_target": "cougar.target",
    "cases._live": "cases._support",
    **{
        f"cases.{name}": f"cases.server.{name}"
        for name in (
            "connect",
            "describe",
            "errors",
            "floats",
            "link",
            "motion",
            "ncp",
            "negative",
            "properties",
            "replies",
            "stateful",
        )
    },
}
"""Old module path (below ``manip.conformance``) -> where the module lives now."""


class _MovedModuleFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Imports an old path of :data:`MOVED` as the module at its new path (one module object, so
    monkeypatching either name patches both)."""

    _own_spec: importlib.machinery.ModuleSpec | None = None

    def find_spec(
        self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        prefix = f"{__name__}."
        if fullname.startswith(prefix) and fullname[len(prefix) :] in MOVED:
            return importlib.machinery.ModuleSpec(fullname, self)
        return None

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        module = importlib.import_module(f"{__name__}.{MOVED[spec.name[len(__name__) + 1 :]]}")
        self._own_spec = module.__spec__
        return module

    def exec_module(self, module: ModuleType) -> None:
        """Nothing to run (the module was imported at its new path); the import system has just given
        it the old path's spec, so its own is put back."""
        module.__spec__ = self._own_spec


if not any(isinstance(f, _MovedModuleFinder) for f in sys.meta_path):
    sys.meta_path.insert(0, _MovedModuleFinder())
