"""Hypothesis profiles: the test command gives the same verdict on every run; a long run searches.

``manip`` (the default): derandomized, so every run draws the same examples; no example database (a
failure is reproduced by the run itself, and ``print_blob`` prints its ``@reproduce_failure``); no
deadline and no too-slow health check, whose verdicts would depend on the machine's load.

``long`` (``MANIP_HYPOTHESIS_PROFILE=long``, see ``tools/hypothesis_long.py``): random examples, at least
``MANIP_HYPOTHESIS_EXAMPLES`` (default 1000) per property test, to find new counterexamples.

Tests' own ``@settings(...)`` objects are built at import, after the profile is loaded here, so they
take everything they do not set (derandomize, database, ...) from it.

Servers in tests, the shared ways (use these rather than a new one):

* a synchronous test that needs a running reference server takes the module-scoped fixture
  :func:`reference_server_url` (a default server on a free loopback port, in a thread of its own);
* an ``async`` test starts one with ``manip.reference_server.driver.serve("tcp://127.0.0.1:0")`` (an
  async context manager: ``server.address`` is where it listens), or a scripted fake with
  ``tests.test_client_tcp.scripted_server``; ``tests.test_client_tcp.in_thread`` runs either in a thread.
"""

from __future__ import annotations

import os
from collections.abc import Iterator

import pytest
from hypothesis import HealthCheck, is_hypothesis_test, settings
from hypothesis.errors import InvalidArgument

PROFILE_VARIABLE = "MANIP_HYPOTHESIS_PROFILE"
EXAMPLES_VARIABLE = "MANIP_HYPOTHESIS_EXAMPLES"
LONG_EXAMPLES = 1000

# Built on Hypothesis's own defaults, whichever profile it chose at import (it picks "ci" on CI machines).
_STEADY = settings(
    settings.get_profile("default"),
    database=None,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
    print_blob=True,
)
settings.register_profile("manip", _STEADY, derandomize=True)


def _long_examples() -> int:
    raw = os.environ.get(EXAMPLES_VARIABLE, "")
    try:
        value = int(raw) if raw else LONG_EXAMPLES
    except ValueError:
        value = 0
    if value < 1:
        raise pytest.UsageError(f"{EXAMPLES_VARIABLE} must be a positive whole number, got {raw!r}")
    return value


def pytest_configure(config: pytest.Config) -> None:
    # Runs before Hypothesis's own hook, so --hypothesis-profile still wins over the variable.
    name = os.environ.get(PROFILE_VARIABLE) or "manip"
    if name == "long":
        settings.register_profile("long", _STEADY, max_examples=_long_examples())
    try:
        settings.load_profile(name)
    except InvalidArgument:
        raise pytest.UsageError(
            f"{PROFILE_VARIABLE}={name!r} is not a Hypothesis profile: use 'long', or leave it unset"
        ) from None


def _settings_holder(item: pytest.Item) -> tuple[object, str] | None:
    """Where a Hypothesis test item keeps its settings: (object, attribute), for a @given test or a
    state machine's TestCase; None for other tests."""
    test = getattr(item, "obj", None)
    if test is None or not is_hypothesis_test(test):
        return None
    if hasattr(test, "_hypothesis_internal_use_settings"):  # Hypothesis's own: no public accessor
        return test, "_hypothesis_internal_use_settings"
    return getattr(item, "cls", None), "settings"  # a state machine's runTest


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Tests marked ``slow`` (whole simulated runs, CPU-bound) come first and, with ``--dist loadgroup``
    (the README's command), go to two workers, one per core, taking turns: the longest then starts at
    once instead of a third of the way in, no more of them than there are cores run at a time, and the
    other workers take the rest, which mostly waits on real-time deadlines.

    ``manip``: refuse a test whose own settings turn derandomization or the database back on.
    ``long``: raise a test's own smaller ``max_examples`` to the profile's."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)  # stable: the rest keep order
    slow = [item for item in items if item.get_closest_marker("slow") is not None]
    for k, item in enumerate(slow):
        item.add_marker(pytest.mark.xdist_group(f"slow-{k % 2}"))
    profile = settings.get_current_profile_name()
    if profile not in ("manip", "long"):
        return
    floor = settings.get_profile("long").max_examples if profile == "long" else 0
    unsteady: list[str] = []
    for item in items:
        holder = _settings_holder(item)
        if holder is None:
            continue
        own: settings = getattr(*holder)
        if profile == "manip" and (not own.derandomize or own.database is not None):
            unsteady.append(item.nodeid)
        elif own.max_examples < floor:
            setattr(*holder, settings(own, max_examples=floor))
    if unsteady:
        raise pytest.UsageError(
            "these tests' @settings undo the derandomized profile (set neither derandomize nor database): "
            + ", ".join(unsteady)
        )


@pytest.fixture(scope="module")
def reference_server_url() -> Iterator[str]:
    """The URL of a default reference server running in a thread, for the tests of one module."""
    from tests.client_cli_support import reference_url

    yield from reference_url()
