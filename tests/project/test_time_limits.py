"""The tests' time limits are a net for a hang, widened for a loaded machine (``tests/conftest.py``)."""

from __future__ import annotations

import os

import pytest

from tests.conftest import TIMEOUT_SCALE, TIMEOUT_SCALE_VARIABLE

SCALE = float(os.environ.get(TIMEOUT_SCALE_VARIABLE) or TIMEOUT_SCALE)


def _limit(request: pytest.FixtureRequest) -> float:
    marker = request.node.get_closest_marker("timeout")
    assert marker is not None
    return float(marker.args[0])


def test_the_default_limit_is_widened(request: pytest.FixtureRequest) -> None:
    assert _limit(request) == float(request.config.getini("timeout")) * SCALE


@pytest.mark.timeout(7, method="thread")
def test_a_tests_own_limit_is_widened_and_keeps_its_method(request: pytest.FixtureRequest) -> None:
    assert _limit(request) == 7 * SCALE
    assert request.node.get_closest_marker("timeout").kwargs == {"method": "thread"}
