"""The numbers Cougar computes: force conversion, GRAVITY, LIMIT, the compliance equation and FILTER.

Pure functions, on numpy arrays where a matrix product is involved and on plain floats where the work
is elementwise (the simulator runs those every tick, and numpy's cost per call would be most of it);
the simulator reads their inputs from Cougar memory and stores the results back.  Units (errata
``cougar-units``): forces in ounces, torques in ounce-inches (the 1985 guide's units for weights and
LIMIT), lengths on the link in millimetres (errata ``units``; converted with 25.4 mm/in where a torque
needs them), joint angles in degrees.  Vectors are in hand coordinates (the end frame of the arm model,
origin at the wrist centre) about the compliance centre, the point the frame vector FV names (§8.2,
B.14).

Conversion (§8.2)::

    voltmat = T(FV) · (−1) · (10/2048) · calmat        force = voltmat · (Y − offsets)

where T(FV) moves a wrench from the wrist centre to the compliance centre: the force rows are unchanged,
the torque rows become τ − r × f.  Only the three torque rows depend on FV, so NFV rewrites just those
(:func:`voltmat_torque_rows`), as the 1985 guide describes.  The −1 makes the force the one the robot applies.

GRAVITY (B.8): hand and object are point masses; ``grav_weight`` is their total (oz) and ``grav_cg`` their
common centre of gravity relative to the compliance centre.  The load gravity puts on the hand is
f = Rᵀ·(0, 0, −weight), τ = cg × f; since the sensed force is the robot's (−1 times the load), the
correction adds that load back: force = sensed + (f, τ).

The compliance equation (B.13; the 1985 guide's "section 1" that describes it is lost, errata
``cougar-compliance-equation``) with the names of Table 1::

    Δx      = J · (θ_sensed − θ_commanded)                    position error at the compliance centre
    Δẋ      = J · (θ̇_sensed − θ̇_commanded)                    the rate difference NPR carries
    F_error = F_commanded − F_sensed − K·Δx − B·Δẋ            NFC, the force, NK (diagonal), NB
    Δθ̇      = BJI · Jᵀ · F_error                              NBJI (diagonal), answered as NTD

A generalised spring and damper: the arm yields to force beyond the commanded one, springs back toward
the commanded position with stiffness K and is damped by B; BJI turns the joint torque Jᵀ·F_error into a
joint-rate modification.  BJI·Jᵀ is computed in the background with J (``P`` in the Jacobian buffer).

FILTER (B.10) then smooths Δθ̇ per joint::

    Δθ̇_filtered = con1·(Δθ̇_sample − Δθ̇_previous sample) − con2·Δθ̇_filtered(previous)
    Δθ̇_output   = con3·Δθ̇_filtered + con4·Δθ̇_sample
    con1 = 2/(aT + 2), con2 = (aT − 2)/(aT + 2)

The defaults con3 = 0, con4 = 1 pass the sample through unchanged.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Final

import numpy as np
import numpy.typing as npt

from manip.arm import PumaGeometry, forward, jacobian
from manip.cougar.adc import VOLTS_PER_COUNT

__all__ = [
    "MM_PER_INCH",
    "centre_jacobian",
    "compliance_sample",
    "cross",
    "filter_constants",
    "gravity_load",
    "gravity_model",
    "hand_rotation",
    "limit",
    "output_filter",
    "skew",
    "voltmat",
    "voltmat_torque_rows",
]

MM_PER_INCH: Final = 25.4
Vector = npt.NDArray[np.float64]
Matrix = npt.NDArray[np.float64]


def skew(v: Vector) -> Matrix:
    """[v]×: the matrix with [v]×·w = v × w."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def cross(a: Sequence[float] | Vector, b: Sequence[float] | Vector) -> list[float]:
    """a × b for 3-vectors, in plain floats: numpy's arithmetic (so its bits) without its cost per call."""
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def voltmat(calmat: Matrix, fv_mm: Vector) -> Matrix:
    """The whole conversion matrix, as one matrix product (the reference for :func:`voltmat_torque_rows`)."""
    t = np.eye(6)
    t[3:, :3] = -skew(np.asarray(fv_mm) / MM_PER_INCH)
    return t @ (-VOLTS_PER_COUNT * np.asarray(calmat).reshape(6, 8))


def voltmat_torque_rows(calmat: Matrix, fv_mm: Vector) -> Matrix:
    """Rows 4-6 of :func:`voltmat`, the only ones FV changes: −(10/2048)·(cal_τ − [r]×·cal_f)."""
    cal = np.asarray(calmat).reshape(6, 8)
    r = np.asarray(fv_mm) / MM_PER_INCH
    return -VOLTS_PER_COUNT * (cal[3:] - skew(r) @ cal[:3])


def gravity_model(
    hand_weight: float, hand_cg_mm: Vector, object_weight: float, object_cg_mm: Vector, fv_mm: Vector
) -> tuple[float, Vector]:
    """Total weight and common cg relative to the compliance centre (mm).

    ``hand_cg_mm`` is from the wrist centre; ``object_cg_mm`` from the frame vector, as NEWWC gives it.
    """
    fv = np.asarray(fv_mm, dtype=np.float64)
    total = hand_weight + object_weight
    if total == 0.0:
        return 0.0, np.zeros(3)
    moment = hand_weight * (np.asarray(hand_cg_mm) - fv) + object_weight * np.asarray(object_cg_mm)
    return total, moment / total


def hand_rotation(theta_deg: Vector | Sequence[float], geometry: PumaGeometry) -> list[list[float]]:
    """Hand-to-world rotation at the given joint angles, as rows (identity if they are not usable angles)."""
    try:
        rows: list[list[float]] = forward(theta_deg, geometry).rotation.tolist()
    except ValueError:
        return [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    return rows


def gravity_load(rotation: Sequence[Sequence[float]], weight: float, cg_mm: Sequence[float]) -> list[float]:
    """The wrench (oz, oz-in; hand axes) gravity puts on a weight at ``cg_mm`` from the reference point:
    f = Rᵀ·(0, 0, −weight), τ = cg × f, with R the hand rotation's rows.

    f is the bottom row of R times −weight: the only products of Rᵀ·(0, 0, −w) that are not exact zeros
    (+ 0.0 makes a zero +0.0, as numpy's matrix product gives it).  Equal to that formulation (a test
    holds them to it).
    """
    w = -weight
    r2 = rotation[2]
    f0, f1, f2 = r2[0] * w + 0.0, r2[1] * w + 0.0, r2[2] * w + 0.0
    a0, a1, a2 = cg_mm[0] / MM_PER_INCH, cg_mm[1] / MM_PER_INCH, cg_mm[2] / MM_PER_INCH
    return [f0, f1, f2, *cross((a0, a1, a2), (f0, f1, f2))]


def limit(force: Sequence[float], dead: float, clamp: float) -> list[float]:
    """LIMIT (B.5): magnitudes below ``dead`` become 0, above ``clamp`` become ±``clamp`` (numpy's
    where(|f| < dead, 0, f) then clip, value by value)."""
    low = -clamp
    return [min(max(0.0 if abs(f) < dead else f, low), clamp) for f in force]


def centre_jacobian(
    theta_deg: Vector | Sequence[float], fv_mm: Vector | Sequence[float], geometry: PumaGeometry
) -> Matrix:
    """J at the compliance centre in hand coordinates: rows mm/deg (translation) and deg/deg (rotation).

    With FV zero (the default) the centre is the wrist centre and J is the end frame's as it is: the
    correction would subtract zeros (changing nothing but, at most, the sign of a zero).
    """
    j = jacobian(theta_deg, geometry, frame="tool")
    if any(fv_mm):
        j[:3] -= skew(np.asarray(fv_mm)) @ j[3:] * (math.pi / 180.0)
    return j


def compliance_sample(
    j: Matrix,
    p: Matrix,
    *,
    k: Vector,
    b: Matrix,
    fc: Vector,
    force: Vector,
    theta_error: Vector,
    rate_difference: Vector,
) -> Vector:
    """Δθ̇ = P·(F_c − F − K·(J·Δθ) − B·(J·Δθ̇)), with P = BJI·Jᵀ from the background."""
    error = fc - force - k * (j @ theta_error) - b @ (j @ rate_difference)
    result: Vector = p @ error
    return result


def filter_constants(cutoff_hz: float, tick_hz: float, con3: float, con4: float) -> tuple[float, ...]:
    """con1..con4 for FILTER with cutoff ``a`` = 2π·cutoff_hz rad/s and sample period T = 1/tick_hz."""
    at = 2.0 * math.pi * cutoff_hz / tick_hz
    return (2.0 / (at + 2.0), (at - 2.0) / (at + 2.0), con3, con4)


def output_filter(
    sample: Vector, previous_sample: Vector, previous_filtered: Vector, con: Vector
) -> tuple[Vector, Vector]:
    """One FILTER step (B.10): (filtered, output)."""
    filtered = con[0] * (sample - previous_sample) - con[1] * previous_filtered
    return filtered, con[2] * filtered + con[3] * sample
