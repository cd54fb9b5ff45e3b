"""manip-conform: the conformance suite for servers of the Chaos manipulator protocol.

* :mod:`~manip.conformance.case`: declaring cases (``@case``), the registry, outcomes as exceptions;
* :mod:`~manip.conformance.context`: :class:`CaseContext` and :class:`Probe`, what a case works with;
* :mod:`~manip.conformance.checks`: pure checkers over recorded packets (reused offline by ``verify``);
* :mod:`~manip.conformance.cases`: the cases themselves, one module per area of the spec;
* :mod:`~manip.conformance.runner`, :mod:`~manip.conformance.report`, :mod:`~manip.conformance.cli`:
  selection, execution, liveness probes, verdict, reports and the ``manip-conform`` command.
"""
