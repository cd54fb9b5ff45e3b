"""Recordings judged and replayed: ``manip-conform replay FILE --against URL`` (``against``), ``--serve
URL`` (``serve``), ``manip-conform verify`` (``verify``), what a replay may not compare (``masking``), the
commands (``cli``) and the report of a capture that cannot be used (``capture_report``).

The names of the old ``manip.conformance.replay`` module are re-exported here, so that import path keeps
working."""

from manip.conformance.replay import against
from manip.conformance.replay.against import *  # noqa: F403 - the old module's names, kept importable here

__all__ = against.__all__
