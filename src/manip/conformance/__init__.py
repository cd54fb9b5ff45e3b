"""manip-conform: the conformance suite for Chaos manipulator servers and Cougar wrist computers.

The package, in the order a run goes through it (``docs/architecture.md`` tells the whole story):

* :mod:`~manip.conformance.suite`: declaring cases (``case``), what a case works with (``context``:
  ``CaseContext``, ``Probe``), running them (``runner``, ``selection``; in virtual time ``embedded`` and
  ``bridge``), their outcomes (``results``) and the suite invariants (``invariants``);
* :mod:`~manip.conformance.judge`: the one violation record, the pure checkers and the stateful model
  (no I/O; reused offline by ``verify`` and replay);
* :mod:`~manip.conformance.cases`: the cases, by the id's target (``server``, ``cougar``, ``client``,
  ``puma``);
* :mod:`~manip.conformance.cougar`: the Cougar target (its word-level probe over the DRV-11J);
* :mod:`~manip.conformance.puma`: the Puma's side of the wrist link (``run --puma`` plays Cougar);
* :mod:`~manip.conformance.client`: judging a client through the harness contract (``manip-conform client``);
* :mod:`~manip.conformance.fuzz`: seeded fuzz campaigns from the spec's tables (``manip-conform fuzz``);
* :mod:`~manip.conformance.replay`: replay against a server, serving a recording, ``verify``, masking;
* :mod:`~manip.conformance.output`: console, packet text, JSON/JUnit reports, coverage;
* :mod:`~manip.conformance.cli`: the ``manip-conform`` command.
"""
