"""The conformance package's moved modules keep their old import paths (one module object each)."""

from __future__ import annotations

import importlib

import pytest

from manip.conformance import MOVED


@pytest.mark.parametrize(("old", "new"), sorted(MOVED.items()))
def test_an_old_path_imports_the_module_at_its_new_path(old: str, new: str) -> None:
    moved = importlib.import_module(f"manip.conformance.{old}")
    module = importlib.import_module(f"manip.conformance.{new}")
    assert moved is module
    assert module.__spec__ is not None and module.__spec__.name == f"manip.conformance.{new}"


def test_the_old_replay_module_names_are_the_replay_package_names() -> None:
    from manip.conformance import replay
    from manip.conformance.replay import against

    assert replay.AnswerSorter is against.AnswerSorter
    assert replay.replay_capture is against.replay_capture
