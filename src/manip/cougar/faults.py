"""Defects the simulated Cougar can be told to have, so the conformance suite can be shown to catch them.

Each fault is a name in :attr:`manip.cougar.CougarConfig.faults` (``manip-cougar --cougar-fault NAME``,
``manip-conform run --cougar sim --cougar-fault NAME``) and is honoured at exactly one place of the
simulator, or of its end of the DRV-11J link for the ``link-*`` ones (:class:`manip.cougar.link.CougarEnd`
and ``manip-cougar``'s server, given the faults by ``serve_cougar``), named below.  A clean Cougar has
none; the mutation test (``tests/conformance/cougar/test_cougar.py``) runs the Cougar cases against each
fault and requires at least one case to fail.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Final

__all__ = ["FAULTS", "parse_faults"]

#: Fault name -> what goes wrong (and where it is honoured).
FAULTS: Final[Mapping[str, str]] = {
    "wrong-version-code": "VERS is answered with response code 3 instead of 8 (CougarSim._version)",
    "no-out-of-sync": "an unknown command code dumps the buffer but sends no out-of-sync message "
    "(CougarSim._comint_run)",
    "guard-trips-twice": "a tripped guard stays armed for one more trip (CougarSim._guardm)",
    "forces-wrong-sign": "the conversion drops the -1: forces are the load on the hand, not the force the "
    "robot applies (CougarSim._convert)",
    "exmn-wrong-count": "EXMN retrieves one word fewer than asked (CougarSim._exp)",
    "comint-executes-partial": "COMINT runs a command whose data words have not all arrived, the missing "
    "ones taken as 0 (Comint.take)",
    "ignores-guardc": "GUARDC leaves the guard armed (CougarSim._guardc)",
    "rst-ignored": "RST leaves the velocities as they were (CougarSim._resetw)",
    "npr-ignores-k": "the compliance equation leaves out the spring term K (CougarSim._newpr)",
    "npr-ignores-fc": "the compliance equation leaves out the commanded force NFC (CougarSim._newpr)",
    "nbji-first-only": "the compliance equation scales every joint by NBJI's first element, not each by "
    "its own (CougarSim._newpr)",
    "filter-con-swapped": "FILTER weighs the filtered value with con4 and the sample with con3 "
    "(CougarSim._newpr)",
    "gravity-fixed-orientation": "GRAVITY takes the hand to be at READY whatever angles SEN or NPR sent "
    "(CougarSim._gravity)",
    "gravity-ignores-cg": "GRAVITY corrects the force of the weight but not its torque about the centre "
    "of gravity (CougarSim._gravity)",
    "nfv-keeps-gravity": "NFV rewrites the conversion matrix but leaves the gravity model about the old "
    "compliance centre (CougarSim._newfv)",
    "nb-transposed": "NPR reads NB's 36 elements column after column instead of row after row "
    "(CougarSim._newpr)",
    "jacobian-transpose-not-stored": "JACOB stores J again where its transpose belongs, after J "
    "(Jacob._encode)",
    "filter-truncates-terms": "ADC8 shifts each term of the sum right by 3 before adding, so a constant "
    "input settles up to 7 counts low (CougarSim._adc8)",
    "guards-sensed-force": "GUARDM tests the sensed force, before GRAVITY's correction (CougarSim._guardm)",
    "compliance-sensed-force": "NPR's compliance equation uses the sensed force, before GRAVITY's "
    "correction (CougarSim._newpr)",
    "rraw-less-offsets": "RRAW reports the readings with the gauge offsets subtracted, not the gauges as "
    "read (CougarSim._reraw)",
    "link-skips-bad-frames": "the DRV-11J link drops a frame it cannot decode (a bad HELLO, an unknown "
    "type, a TICK of the wrong length) and carries on (FrameDecoder.feed, for CougarEnd)",
    "link-ignores-wrong-side": "the link takes a HELLO naming the Cougar's own role and ignores frames "
    "only Cougar sends (COUGAR, TICKED) instead of ending (CougarEnd)",
    "link-hello-optional": "the link takes a first frame that is not HELLO as if HELLO had come before it "
    "(_End._frames)",
    "link-ignores-version": "the link takes a HELLO of any version, not only 1 (_End._frames)",
    "link-tick-backwards-runs": "a TICK earlier than the one before it runs at the earlier tick's time "
    "instead of ending the link (CougarEnd._model_time)",
    "link-ignores-bye": "the link carries on after the Puma's BYE (CougarEnd, _End._frames)",
    "link-busy-serves-second": "a second Puma connecting while one is linked is served too, not sent "
    "BYE 'busy' (CougarServer._handle)",
}


def parse_faults(names: Iterable[str]) -> frozenset[str]:
    """The set of fault names; ValueError naming the known ones for an unknown name."""
    chosen = frozenset(n.strip() for n in names if n.strip())
    unknown = sorted(chosen - FAULTS.keys())
    if unknown:
        raise ValueError(f"unknown Cougar fault(s) {unknown}; known: {', '.join(sorted(FAULTS))}")
    return chosen
