"""Cougar, the wrist PDP-11, simulated behind its 16-bit word protocol (the 1985 guide, Part III,
Appendices B, C).

:class:`CougarSim` is sans-I/O: ``receive(words)`` buffers words from the Puma, ``tick(now)`` runs one
Puma clock tick (GUTS: ADC8, conversion, GRAVITY, guards, COMINT; then the background JACOB) and returns
the words Cougar sends.  ``memory`` is its 16-bit memory (:mod:`manip.cougar.memory` has the map) and
``stats`` its counters.  The environment (:class:`Surface`, :class:`Spring`, :class:`FreeSpace`) gives the
contact wrench at the pose of the joint angles Cougar was last sent.
"""

from manip.cougar.adc import GaugeModel, adc8_filter
from manip.cougar.environment import Contacts, Environment, FreeSpace, Spring, Surface, Wrench
from manip.cougar.memory import MAP, Memory, Region, format_map
from manip.cougar.sim import CougarConfig, CougarSim, CougarStats

__all__ = [
    "MAP",
    "Contacts",
    "CougarConfig",
    "CougarSim",
    "CougarStats",
    "Environment",
    "FreeSpace",
    "GaugeModel",
    "Memory",
    "Region",
    "Spring",
    "Surface",
    "Wrench",
    "adc8_filter",
    "format_map",
]
