"""Hypothesis profiles: the test command gives the same verdict on every run; a long run searches.

``manip`` (the default): derandomized, so every run draws the same examples; no example database (a
failure is reproduced by the run itself, and ``print_blob`` prints its ``@reproduce_failure``); no
deadline and no too-slow health check, whose verdicts would depend on the machine's load.

``long`` (``MANIP_HYPOTHESIS_PROFILE=long``, see ``tools/hypothesis_long.py``): random examples, at least
``MANIP_HYPOTHESIS_EXAMPLES`` (default 1000) per property test, to find new counterexamples.

Tests' own ``@settings(...)`` objects are built at import, after the profile is loaded here, so they
take everything they do not set (derandomize, database, ...) from it.

Servers in tests, the shared ways (``tests/support/servers.py``; use these rather than a new one):

* a synchronous test that needs a running reference server takes the module-scoped fixture
  :func:`reference_server_url` (or :func:`chudp_server_url`), or :func:`served` for one of its own set up
  by a :class:`tests.support.servers.ServerOptions` (faults, link kind, contact) given with
  ``@pytest.mark.parametrize("served", [ServerOptions(...)], indirect=True)``: the server runs in a
  thread and the test's own event loop, if it has one, is the client's;
* an ``async`` test that needs the server in its own loop uses ``tests.support.servers.running_server`` or
  ``reference_server``, or a scripted fake with ``tests.support.servers.scripted_server``;
  ``tests.support.servers.in_thread`` runs any of them in a thread;
* a test of a command itself (``manip-server``, ``manip-cougar``) takes :func:`manip_server`, which
  starts the command as a process on a free port and stops and reaps it at teardown.
"""

from __future__ import annotations

import gc
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any


def _cache_bytecode_in_the_venv() -> None:
    """Where the environment forbids bytecode files (``PYTHONDONTWRITEBYTECODE``, usually to keep
    ``__pycache__`` out of source trees), keep them in the test run's virtualenv instead.

    Without any cache every xdist worker rewrites and compiles all test modules (about 5 s of CPU each)
    and every Python process a test starts compiles manip again (0.1 s or more); with it, the source
    tree still gets no ``__pycache__``.  Set for this process and, through the environment, for the
    workers and the commands the tests start.  Left alone where Python writes bytecode anyway, or where
    the interpreter's prefix is not a writable virtualenv."""
    if not sys.dont_write_bytecode or sys.prefix == sys.base_prefix:
        return
    prefix = Path(sys.prefix) / "pycache"
    try:
        prefix.mkdir(exist_ok=True)
    except OSError:
        return
    if not os.access(prefix, os.W_OK):
        return
    sys.pycache_prefix = str(prefix)
    sys.dont_write_bytecode = False
    os.environ["PYTHONPYCACHEPREFIX"] = str(prefix)
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)


_cache_bytecode_in_the_venv()

import pytest  # noqa: E402  # after the bytecode setting, so that what follows is cached too
from hypothesis import HealthCheck, is_hypothesis_test, settings  # noqa: E402
from hypothesis.errors import InvalidArgument  # noqa: E402

if TYPE_CHECKING:
    from manip.reference_server.driver import ReferenceServer
    from tests.support.servers import ServerProcess, StartServer

PROFILE_VARIABLE = "MANIP_HYPOTHESIS_PROFILE"
EXAMPLES_VARIABLE = "MANIP_HYPOTHESIS_EXAMPLES"
LONG_EXAMPLES = 1000
TIMEOUT_SCALE_VARIABLE = "MANIP_TIMEOUT_SCALE"
TIMEOUT_SCALE = 4.0
"""Every test's time limit (pytest-timeout's, the ini's 120 s or the test's own ``timeout`` mark) is
multiplied by this (``MANIP_TIMEOUT_SCALE`` overrides it).  A limit is a net for a test that hangs, never a
judgement of speed: the limits were set from idle runs, and on a loaded machine (two cores at a load of
12 or more, as when other jobs share CI's machine) whole simulated runs take five times as long, and a
limit hit in the middle of one fails it with a misleading message.  Speed is judged in ``bench/``."""

# Built on Hypothesis's own defaults, whichever profile it chose at import (it picks "ci" on CI machines).
_STEADY = settings(
    settings.get_profile("default"),
    database=None,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
    print_blob=True,
)
settings.register_profile("manip", _STEADY, derandomize=True)


def _positive(variable: str, default: float) -> float:
    raw = os.environ.get(variable, "")
    try:
        value = float(raw) if raw else default
    except ValueError:
        value = 0.0
    if not value > 0:
        raise pytest.UsageError(f"{variable} must be a positive number, got {raw!r}")
    return value


def _widen_time_limits(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Each test's time limit, times :data:`TIMEOUT_SCALE`: a mark placed first, which pytest-timeout
    reads as the test's own (its other settings, such as ``method``, kept)."""
    scale = _positive(TIMEOUT_SCALE_VARIABLE, TIMEOUT_SCALE)
    default = float(config.getini("timeout") or 0)
    for item in items:
        own = item.get_closest_marker("timeout")
        kwargs = dict(own.kwargs) if own else {}
        limit = own.args[0] if own and own.args else kwargs.pop("timeout", None)
        limit = default if limit is None else float(limit)
        if limit > 0:
            item.add_marker(pytest.mark.timeout(limit * scale, **kwargs), append=False)


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


def pytest_collection_finish(session: pytest.Session) -> None:
    """What collection built (test modules, parametrisations, Hypothesis strategies) lives as long as the
    process: moved out of the collector's way, it is not traversed again by every full collection that
    the simulated runs set off (half their cost in a worker)."""
    gc.freeze()


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Tests marked ``slow`` (whole simulated runs, CPU-bound) come first and, with ``--dist loadgroup``
    (the README's command), go to two workers, one per core, taking turns: the longest then starts at
    once instead of a third of the way in, no more of them than there are cores run at a time, and the
    other workers take the rest.  Of the rest, those marked ``waits`` (real-time tests that mostly wait)
    go first, so that their waiting overlaps the CPU-bound tests instead of ending the run alone (a
    fuzzing test that waits out a hang once ran for the last 23 s with every other worker done).

    Every time limit is widened by :data:`TIMEOUT_SCALE`.

    ``manip``: refuse a test whose own settings turn derandomization or the database back on.
    ``long``: raise a test's own smaller ``max_examples`` to the profile's."""
    _widen_time_limits(config, items)

    def rank(item: pytest.Item) -> int:
        return 0 if item.get_closest_marker("slow") else 1 if item.get_closest_marker("waits") else 2

    items.sort(key=rank)  # stable: within a rank the tests keep their order
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


# The servers' modules are imported when a test first asks for one: collection stays light.
@pytest.fixture(scope="module")
def reference_server_url() -> Iterator[str]:
    """The URL of a default reference server running in a thread, for the tests of one module."""
    from tests.support.servers import in_thread, reference_server

    with in_thread(reference_server()) as address:
        yield address


@pytest.fixture(scope="module")
def chudp_server_url() -> Iterator[str]:
    """The same on CHUDP."""
    from tests.support.servers import LINK_ADDRESSES, in_thread, reference_server

    with in_thread(reference_server(address=LINK_ADDRESSES["chudp"])) as address:
        yield address


@pytest.fixture
def served(request: pytest.FixtureRequest) -> Iterator[ReferenceServer]:
    """A reference server in a thread for one test, set up by the ``ServerOptions`` the test gives as
    an indirect parameter (the defaults without one); ``served.address`` is where it listens."""
    from tests.support.servers import ServerOptions, in_thread

    options = getattr(request, "param", ServerOptions())
    assert isinstance(options, ServerOptions), options
    with in_thread(options.start()) as server:
        yield server


@pytest.fixture
def manip_server() -> Iterator[StartServer]:
    """``manip_server(*args, **options)`` starts a server command as a process
    (:func:`tests.support.servers.start_process`); every one it started is stopped and reaped at teardown."""
    from tests.support.servers import start_process

    started: list[ServerProcess] = []

    def start(*args: str, **options: Any) -> ServerProcess:
        server = start_process(*args, **options)
        started.append(server)
        return server

    yield start
    for server in reversed(started):  # the last started may use the ones before it
        server.end()


def _skip_reason(report: pytest.TestReport) -> str:
    """A skip's reason: pytest keeps it as (path, line, reason), and so does a report from an xdist worker."""
    longrepr = report.longrepr
    if isinstance(longrepr, tuple | list) and len(longrepr) == 3:
        return str(longrepr[2])
    return str(longrepr)


@pytest.hookimpl(wrapper=True, tryfirst=True)
def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> Iterator[None]:
    """The run ends with one line naming what was not checked for want of a real program and how to
    install it (``tests/support/programs.py``), after every other summary (the outermost wrapper: after
    ``-ra``'s list of skips too), just before the count of tests.  It reads the skips the terminal
    reporter collected, which on the xdist controller are the workers' reports, and shows with ``-q``."""
    from tests.support.programs import missing_from, summary_line

    yield
    skipped = terminalreporter.stats.get("skipped", [])
    line = summary_line(missing_from(_skip_reason(report) for report in skipped))
    if line is not None:
        terminalreporter.write_line(line, yellow=True, bold=True)
