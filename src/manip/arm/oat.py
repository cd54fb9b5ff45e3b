"""VAL's x, y, z, O, A, T pose description, as the incremental moves (opcodes 0211, 0212) use it.

Model implemented: **H1** of docs/kinematics.md §2.2, built from the 1977 VAL manual's
text.  With O = A = T = 0 the hand points along −Y (a = (0, −1, 0)), the fingers lie in a horizontal
plane with the finger-to-finger vector along X (o = (1, 0, 0)), so n = o × a = (0, 0, −1).  O turns the
hand about the world vertical (pre-multiply), A tilts the approach about the hand's o axis and T rolls
about the approach (post-multiply), all right-handed::

    R(O, A, T) = Rz(O) · R0 · Ry(A) · Rz(T) = Rz(O − 90°) · Ry(A + 90°) · Rz(T)      R0 = [n o a] above

so A = +90° points the hand straight down and A = −90° straight up.  The signs of A and T are not
confirmed by a primary source (docs/kinematics.md §2.4); if VAL differs, negate A and/or T here and
nothing else changes.

Singular cases: when the approach vector is vertical (A = ±90°) only one combination of O and T is
defined: O + T when the hand points up, O − T when it points down.  :func:`xyzoat_from_transform` then
keeps T at a value the caller chooses (``singular_t``, default 0) and solves for O, so the angles it
returns always rebuild the same rotation.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from manip.arm.transform import Transform

__all__ = [
    "OAT_SINGULAR_TOL_DEG",
    "XYZOAT",
    "add_increment",
    "apply_increment",
    "rotation_from_oat",
    "transform_from_xyzoat",
    "wrap_deg",
    "xyzoat_from_transform",
]

#: (x, y, z, O, A, T): millimetres and degrees.
XYZOAT = tuple[float, float, float, float, float, float]

#: Tilt of the approach vector from the vertical (deg) below which a pose is treated as singular.
#: Below it the O/T split is numerically meaningless; the rotation rebuilt from the returned angles is
#: off by at most this angle.
OAT_SINGULAR_TOL_DEG = 1e-6


def wrap_deg(angle: float) -> float:
    """Wrap an angle in degrees into (−180, 180]."""
    w = math.fmod(angle, 360.0)
    if w <= -180.0:
        w += 360.0
    elif w > 180.0:
        w -= 360.0
    return w


def _rz(deg: float) -> NDArray[np.float64]:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ry(deg: float) -> NDArray[np.float64]:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rotation_from_oat(o: float, a: float, t: float) -> NDArray[np.float64]:
    """The 3x3 hand rotation of VAL angles O, A, T (degrees), model H1."""
    return _rz(o - 90.0) @ _ry(a + 90.0) @ _rz(t)


def transform_from_xyzoat(x: float, y: float, z: float, o: float, a: float, t: float) -> Transform:
    """Pose from VAL's position (mm) and O, A, T angles (degrees), model H1."""
    return Transform.from_rotation_translation(rotation_from_oat(o, a, t), (x, y, z))


def xyzoat_from_transform(
    pose: Transform, *, singular_t: float = 0.0, tol_deg: float = OAT_SINGULAR_TOL_DEG
) -> XYZOAT:
    """VAL's (x, y, z, O, A, T) of a pose; A in [−90, 90], O and T wrapped into (−180, 180].

    When the approach vector is within ``tol_deg`` of vertical, T is set to ``singular_t`` (wrapped)
    and O carries the whole rotation about the vertical (see the module docstring).
    """
    r = pose.rotation
    ax, ay, az = float(r[0, 2]), float(r[1, 2]), float(r[2, 2])
    horiz = math.hypot(ax, ay)
    theta = math.degrees(math.atan2(horiz, az))  # ZYZ middle angle, in [0, 180]
    if theta <= tol_deg or theta >= 180.0 - tol_deg:
        # Treated as vertical: A is exactly ±90, so the rebuilt rotation is off by the tilt only
        # (keeping the tilt would point it the wrong way as well, doubling the error).
        theta = 0.0 if az > 0.0 else 180.0
        t = wrap_deg(singular_t)
        if az > 0.0:  # hand up: R ≈ Rz(φ + ψ)
            phi = math.degrees(math.atan2(float(r[1, 0]), float(r[0, 0]))) - t
        else:  # hand down: R ≈ Rz(φ − ψ)·Ry(180°)
            phi = math.degrees(math.atan2(-float(r[0, 1]), float(r[1, 1]))) + t
    else:
        phi = math.degrees(math.atan2(ay, ax))
        t = math.degrees(math.atan2(float(r[2, 1]), -float(r[2, 0])))
    x, y, z = (float(v) for v in pose.p)
    return (x, y, z, wrap_deg(phi + 90.0), theta - 90.0, wrap_deg(t))


def add_increment(current: XYZOAT, delta: XYZOAT) -> XYZOAT:
    """Component-wise sum of a pose and an increment; angles are left unwrapped so A may pass ±90°."""
    return (
        current[0] + delta[0],
        current[1] + delta[1],
        current[2] + delta[2],
        current[3] + delta[3],
        current[4] + delta[4],
        current[5] + delta[5],
    )


def apply_increment(
    pose: Transform,
    dx: float,
    dy: float,
    dz: float,
    do: float,
    da: float,
    dt: float,
    *,
    oat: tuple[float, float, float] | None = None,
) -> Transform:
    """Target pose of an incremental move (opcodes 0211/0212): dX dY dZ in world mm, dO dA dT in degrees.

    Decision: the position increment is added in world (table) coordinates, and dO, dA, dT are added to
    the current O, A, T angles, then the rotation is rebuilt: T_new = Trans(p + d)·R(O + dO, A + dA,
    T + dT).  Pass the last commanded angles as ``oat`` when you have them: near a vertical approach,
    angles re-extracted from ``pose`` split O and T arbitrarily, and adding dO or dT to that split gives
    a different motion than the client meant.  Without ``oat`` they are extracted from ``pose``.
    """
    x, y, z = (float(v) for v in pose.p)
    if oat is None:
        _, _, _, o, a, t = xyzoat_from_transform(pose)
    else:
        o, a, t = oat
    return transform_from_xyzoat(*add_increment((x, y, z, o, a, t), (dx, dy, dz, do, da, dt)))
