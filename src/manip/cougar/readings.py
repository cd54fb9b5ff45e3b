"""Other readings of the 1985 guide the simulated Cougar can be told to take, so the conformance suite can
be shown to accept every reading the guide allows.

A reading is not a fault: where the guide is silent or says two things, manip picks one behaviour for its
Cougar (each one has its erratum) and a Cougar written from the guide alone may pick another.  Each name
in :attr:`manip.cougar.CougarConfig.readings` (``manip-cougar --cougar-reading NAME``,
``manip-conform run --cougar sim --cougar-reading NAME``) switches the simulator to the other reading at
exactly one place, named below, and ``tests/conformance/cougar/test_readings.py`` runs the Cougar cases
against each and requires the run to pass.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Final

__all__ = ["MAP_SHIFT", "READINGS", "parse_readings"]

MAP_SHIFT: Final = 0o20000
"""How far ``relocated-map`` moves the whole memory map up, in bytes."""

#: Reading name -> what changes (and where it is honoured).
READINGS: Final[Mapping[str, str]] = {
    "exmn-always-full": "EXMN always answers the count asked (Table 1: 'at least 2 words'): an odd address "
    "is read from the word below it, words outside memory read as 0 (CougarSim._exp)",
    "out-of-sync-bare": "the out-of-sync message is the code word 2 alone, without the offending word "
    "(CougarSim._comint_run)",
    "guard-trips-above-tol": "a guard trips only when the dot product exceeds tol, not when it equals it "
    "(CougarSim._guardm)",
    "guard-hi-bit-only": "only bit 15 of the type word makes a stop guard (Table 1's 'hi bit'); another "
    "high-byte bit alone makes it continue (CougarSim._guards)",
    "guts-every-tick": "every TICK runs a whole GUTS however soon it follows the previous one: no GUTS "
    "cost model (CougarSim.tick)",
    "lengths-in-inches": "the frame vector (NFV) and the centre of gravity (NEWWC) are in inches, as the "
    "guide's ounce-inch torques suggest, not millimetres (CougarSim._lengths_mm)",
    "filter-rounds-to-nearest": "ADC8 rounds its division by 8 to the nearest count (ties to even) "
    "instead of flooring it with an arithmetic shift (CougarSim._adc8)",
    "offsets-after-filter": "the gauge offsets are subtracted from the filtered readings, after ADC8's "
    "filter; RRAW reports the filtered readings (CougarSim._adc8)",
    "rraw-unfiltered": "RRAW reports the latest gauge samples as read, before the filter and the "
    "offsets ('readings from each of the 8 wrist strain gauges'), not the filtered readings "
    "(CougarSim._reraw)",
    "relocated-map": f"the memory map sits {MAP_SHIFT:#o} bytes higher on the link, as another Cougar's "
    "own map would: the memory above the vectors is rotated by that much (CougarSim._inside)",
}


def parse_readings(names: Iterable[str]) -> frozenset[str]:
    """The set of reading names; ValueError naming the known ones for an unknown name."""
    chosen = frozenset(n.strip() for n in names if n.strip())
    unknown = sorted(chosen - READINGS.keys())
    if unknown:
        raise ValueError(f"unknown Cougar reading(s) {unknown}; known: {', '.join(sorted(READINGS))}")
    return chosen
