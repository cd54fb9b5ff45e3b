"""Cougar target cases (``manip-conform run --cougar URL``): Table 1 and Appendix B over the DRV-11J,
one module per topic.

Each case opens its own link (:func:`~manip.conformance.cougar.probe.cougar_probe`) and plays the Puma,
tick by tick.  A Cougar keeps its state across links (as the real one did across Puma sessions), so a
case never assumes a fresh one: it disarms every guard first (``_support.clean``), sets the parameters it
relies on, lets the gauge filter settle when it reads forces, and puts back what it changed that a Puma
would not set again (gauge offsets, frame vector, version word).

What a case may rely on, so that it holds for any conforming Cougar and not just manip's simulator:

* Table 1 (codes, data lengths) and the 1985 guide's GUTS order: ADC8, conversion, GRAVITY, guards, COMINT,
  one GUTS per Puma tick; a response may come up to :data:`DEFAULT_WITHIN` ticks after its command.
* Only what every reading of the 1985 guide gives; where it allows more than one behaviour, each is
  accepted (the simulator's readings, :mod:`manip.cougar.readings`, prove it): out-of-sync is response 2,
  alone or with the bad word (``cougar-out-of-sync``); bit 15 of a guard's first word makes it stop and
  a clear high byte continue (``guard-type-bit``); a guard trips above tol and not below it
  (``guard-trip-comparison``); one GUTS per TICK or a dropped TICK (``cougar-guts-reentry``).
* Memory addresses only from the run's memory map (``--memory-map``, ``ctx.options.cougar_map``;
  erratum ``cougar-memory-map``): a case that needs an object the map does not give is not judged
  (``_support.mapped``); lengths in the run's unit (``--length-unit``, ``cougar-length-unit``).
* ADC8's rounding (``cougar-filter-rounding``: any rounding of the division, a settled reading within 3
  counts); the conversion and force sign (``cougar-units``); the compliance equation
  (``cougar-compliance-equation``), used through properties that any linear spring/damper law has (zero
  gain gives zero, doubling a gain doubles its effect), and for NB's row order through the Jacobian the
  Cougar itself holds; GRAVITY's point-mass model with the hand's orientation from the Puma 560's
  kinematics (``manip.arm``), the frame the Cougar's forces are in.
* Each value checked on its own (a gauge, a guard, a row block), so a case reports every violation.
* Never the simulator's numbers: no expected force, gauge or Δθ value is hard-coded; each check compares
  Cougar with itself (before/after, split/unsplit) or with a formula of the spec applied to what Cougar
  reports (or, for gravity, to the weight and centre of gravity the case sends).
* The DRV-11J link's error paths (``link_errors``) on raw connections, the link being manip's own
  contract (``docs/drv11j.md``).
"""
