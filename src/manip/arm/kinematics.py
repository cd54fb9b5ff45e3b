"""Exact kinematics of a PUMA-type arm in the Lee/VAL joint convention (millimetres, degrees).

The protocol's "solve backwards" (joint angles to transform) is :func:`forward`; its "solve forwards"
(transform to joint angles) is :func:`inverse_nearest`, built on the closed-form :func:`inverse_all`.

Convention (errata ``joint-convention``): standard Denavit-Hartenberg, A_i = Rz(θ_i)·Tz(d_i)·Tx(a_i)·Rx(α_i),
with the Lee & Ziegler / Fu-Gonzalez-Lee table (docs/kinematics.md §1)::

    joint   α     a      d
      1    −90    0      0
      2      0   a2     d2      (d2: shoulder offset)
      3    +90  −a3      0
      4    −90    0     d4
      5    +90    0      0
      6      0    0     d6      (d6 = 0: the end frame is the wrist centre)

The world origin is on the J1 axis at shoulder height.  Ready, (0, −90, 90, 0, 0, 0), points the arm
straight up with the end frame aligned with the world.  The roboticstoolbox (Corke) convention maps onto
this one exactly: q_Lee = q_RTB + (0, 180, 180, 0, 0, 0), with world and tool frames turned 180° about z.

The PUMA 600 has no published geometry of its own, so it is modelled with the PUMA 560's
(:data:`PUMA560_LEE`); pass another :class:`PumaGeometry` for other numbers.

Inverse kinematics follows Pieper's split: joints 1-3 place the wrist centre p − d6·a (two waist
solutions, lefty/righty, times two elbow solutions, above/below), and joints 4-6 are the ZYZ Euler angles
of R03ᵀ·R, because with this table R36 = Rz(θ4)·Ry(θ5)·Rz(θ6) (two wrist solutions, noflip/flip).
"""

from __future__ import annotations

import functools
import itertools
import math
import struct
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import ClassVar, Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray

from manip.arm.oat import wrap_deg
from manip.arm.transform import Transform

__all__ = [
    "LEE_FLANGE_MM",
    "LIMIT_TOL_DEG",
    "PUMA560_CORKE",
    "PUMA560_LEE",
    "PUMA600",
    "REACH_TOL_MM",
    "READY",
    "UNIMATION_LIMITS",
    "WRIST_SINGULAR_DEG",
    "ArmModel",
    "JointLimits",
    "Joints",
    "JointsLike",
    "KinematicsError",
    "OutOfRange",
    "PumaGeometry",
    "Solution",
    "Unreachable",
    "configuration",
    "forward",
    "forward_rows",
    "inverse_all",
    "inverse_nearest",
    "jacobian",
    "joint_mask",
    "nearest_solution",
    "within_limits",
]

Joints = tuple[float, float, float, float, float, float]
#: What the public functions accept for joint angles (deg): any 6-sequence of floats or a float array.
JointsLike = Sequence[float] | NDArray[np.float64]
Matrix = NDArray[np.float64]
#: A 3x3 matrix as rows of plain floats.
Rows = Sequence[Sequence[float]]

#: |J5| (deg) below which the wrist counts as singular and J4 is held at the reference (current) value,
#: or the in-range angle nearest it.
#: A pose rebuilt from such a solution is off by at most this angle.  Poses with J5 = 0 rounded to
#: 24-bit PDP-11 floats come back with |J5| ~ 2e-6° typically and ~1e-4° at the 99th percentile (measured
#: on random poses), so they take the singular branch instead of spinning J4 to an arbitrary angle.
WRIST_SINGULAR_DEG = 1e-3
#: Slack (mm) on the workspace boundary: a pose up to this far outside it is solved as if on it, because
#: rounding to 24-bit floats (~6e-5 mm at 1 m) can push a boundary pose, e.g. one with the wrist centre on
#: the shoulder-offset cylinder, just outside.
REACH_TOL_MM = 1e-3
#: Slack (deg) when comparing joint angles with their limits.
LIMIT_TOL_DEG = 1e-9
#: Lee's flange distance d6 from the wrist centre (mm); use it as ``PumaGeometry.d6`` for a flange frame.
LEE_FLANGE_MM = 56.25


@dataclass(frozen=True)
class PumaGeometry:
    """Link dimensions (mm) of a six-joint PUMA-type arm with a spherical wrist, in the table above."""

    a2: float
    """Upper arm length (shoulder to elbow)."""
    a3: float
    """Elbow offset; Lee's table lists it as DH a3 = −a3."""
    d2: float
    """Shoulder offset along the J2 axis."""
    d4: float
    """Forearm length (elbow to wrist centre)."""
    d6: float = 0.0
    """Wrist centre to the end frame along the approach vector."""
    name: str = ""

    def __post_init__(self) -> None:
        for name in ("a2", "a3", "d2", "d4", "d6"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"PumaGeometry.{name} must be finite")
        if self.a2 <= 0.0 or math.hypot(self.a3, self.d4) <= 0.0:
            raise ValueError("PumaGeometry needs a2 > 0 and a non-zero forearm")

    def dh(self) -> tuple[tuple[float, float, float], ...]:
        """Standard-DH rows (α deg, a mm, d mm) for joints 1-6."""
        return (
            (-90.0, 0.0, 0.0),
            (0.0, self.a2, self.d2),
            (90.0, -self.a3, 0.0),
            (-90.0, 0.0, self.d4),
            (90.0, 0.0, 0.0),
            (0.0, 0.0, self.d6),
        )


#: The PUMA 560 as given by Lee & Ziegler 1984 and Fu-Gonzalez-Lee 1987 (also the comp.robotics FAQ):
#: a2 = 431.8, a3 = 20.32, shoulder offset 149.09, d4 = 433.07 mm; end frame at the wrist centre.
#: Used for the MIT PUMA 600 (errata ``joint-convention``).
PUMA560_LEE = PumaGeometry(
    a2=431.8, a3=20.32, d2=149.09, d4=433.07, d6=0.0, name="PUMA 560 (Lee/FGL numbers)"
)
#: The same arm with roboticstoolbox-python's numbers (without its 671.83 mm pedestal), for comparisons.
PUMA560_CORKE = PumaGeometry(
    a2=431.8, a3=20.3, d2=150.05, d4=431.8, d6=0.0, name="PUMA 560 (roboticstoolbox)"
)

#: The ready position: arm straight up.
READY: Joints = (0.0, -90.0, 90.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class JointLimits:
    """Inclusive joint ranges in degrees, joint 1 first."""

    lower: tuple[float, ...]
    upper: tuple[float, ...]

    def __post_init__(self) -> None:
        if len(self.lower) != 6 or len(self.upper) != 6:
            raise ValueError("JointLimits needs six lower and six upper bounds")
        for j, (lo, hi) in enumerate(zip(self.lower, self.upper, strict=True), start=1):
            if not lo < hi:
                raise ValueError(f"joint {j}: lower limit {lo} is not below upper limit {hi}")

    def violations(self, q: JointsLike, tol: float = LIMIT_TOL_DEG) -> list[int]:
        """1-based numbers of the joints of ``q`` outside their range."""
        return [
            j
            for j, (v, lo, hi) in enumerate(zip(_as_joints(q), self.lower, self.upper, strict=True), start=1)
            if not lo - tol <= v <= hi + tol
        ]

    def representations(self, j: int, angle: float, tol: float = LIMIT_TOL_DEG) -> list[float]:
        """Every angle ≡ ``angle`` (mod 360) within joint ``j``'s range (1-based), nearest to it first."""
        lo, hi = self.lower[j - 1], self.upper[j - 1]
        k_min = math.ceil((lo - tol - angle) / 360.0)
        k_max = math.floor((hi + tol - angle) / 360.0)
        return sorted((angle + 360.0 * k for k in range(k_min, k_max + 1)), key=lambda v: abs(v - angle))


#: Unimation's ranges in the Lee/VAL convention (docs/kinematics.md §1).
UNIMATION_LIMITS = JointLimits(
    lower=(-160.0, -225.0, -45.0, -110.0, -100.0, -266.0),
    upper=(160.0, 45.0, 225.0, 170.0, 100.0, 266.0),
)


@dataclass(frozen=True)
class ArmModel:
    """Everything the simulator needs to know about one arm's kinematics."""

    geometry: PumaGeometry
    limits: JointLimits
    ready: Joints = READY
    name: str = ""


#: The MIT AI Lab PUMA 600, modelled as a PUMA 560 with Lee's numbers and Unimation's joint ranges.
PUMA600 = ArmModel(PUMA560_LEE, UNIMATION_LIMITS, READY, "MIT AI Lab PUMA 600")


# ------------------------------------------------------------------------------------------ errors
class KinematicsError(ValueError):
    """A transform the arm cannot take; ``error_code`` is the protocol error a server answers."""

    error_code: ClassVar[str] = ""


class Unreachable(KinematicsError):  # noqa: N818 -- the name the protocol layer uses
    """No joint angles reach the transform at all, whatever the limits (protocol error TOR, erratum
    ``transform-refusals``)."""

    error_code: ClassVar[str] = "TOR"

    def __init__(self, reason: str) -> None:
        super().__init__(f"transform unreachable: {reason}")
        self.reason = reason


class OutOfRange(KinematicsError):  # noqa: N818 -- the name the protocol layer uses
    """The transform is reachable, but every solution breaks a joint limit (protocol error TOR, the 1985
    guide's "solution of a transform resulted in out-of-range joints"; erratum ``transform-refusals``).

    ``joints`` are the joints (1-based) the closest configuration breaks: the configuration with fewest
    offending joints, ties going to the one nearest the current angles.  ``mask`` is the same set as the
    error's ``$`` joint bit mask (bit 0 = joint 1).
    """

    error_code: ClassVar[str] = "TOR"

    def __init__(self, joints: Sequence[int], solutions: Sequence[Solution]) -> None:
        self.joints = tuple(joints)
        self.solutions = tuple(solutions)
        names = ", ".join(f"J{j}" for j in self.joints)
        super().__init__(f"every solution breaks a joint limit; nearest configuration breaks {names}")

    @property
    def mask(self) -> int:
        return joint_mask(self.joints)


def joint_mask(joints: Iterable[int]) -> int:
    """The protocol's ``$`` joint mask of 1-based joint numbers: bit 0 is joint 1."""
    mask = 0
    for j in joints:
        if j < 1:
            raise ValueError(f"joint numbers start at 1, got {j}")
        mask |= 1 << (j - 1)
    return mask


def within_limits(q: JointsLike, limits: JointLimits = UNIMATION_LIMITS) -> list[int]:
    """1-based numbers of the joints of ``q`` outside ``limits`` (empty when all are in range)."""
    return limits.violations(q)


# ------------------------------------------------------------------------------------------ forward
def _as_joints(q: JointsLike) -> Joints:
    """Validate and copy joint angles: exactly six finite numbers."""
    if len(q) != 6:
        raise ValueError(f"expected 6 joint angles, got {len(q)}")
    v: Joints = tuple(map(float, q))  # type: ignore[assignment]  # six, checked above
    if not all(map(math.isfinite, v)):
        raise ValueError(f"joint angles must be finite, got {v}")
    return v


# Exact cos/sin of the table's twists, so that zero entries stay exactly zero.
_TWIST = {-90.0: (0.0, -1.0), 0.0: (1.0, 0.0), 90.0: (0.0, 1.0)}
_EYE4: Matrix = np.eye(4)
_EYE4.flags.writeable = False
_JOINT_BITS = struct.Struct("<6d")


def _frames(q_deg: Joints, geometry: PumaGeometry) -> tuple[Matrix, ...]:
    """Base-to-frame-i transforms for i = 0..6, read-only.

    The simulated Cougar asks for the same angles several times a tick (the physical load, GRAVITY's
    hand rotation, JACOB's Jacobian), so the last few answers are kept.  The key is the angles' bits:
    -0.0 and 0.0 are equal as floats but give links whose zeros differ in sign.
    """
    return _frames_of(_JOINT_BITS.pack(*q_deg), geometry)


@functools.lru_cache(maxsize=32)
def _frames_of(key: bytes, geometry: PumaGeometry) -> tuple[Matrix, ...]:
    # One array holds the six link matrices A_i = Rz(θ_i)·Tz(d_i)·Tx(a_i)·Rx(α_i); the chain is then
    # multiplied from the identity one link at a time, the same matrix products (so the same bits) as
    # building and multiplying one 4x4 array per link, for half the cost.
    entries: list[float] = []
    for qi, (alpha, a, d) in zip(_JOINT_BITS.unpack(key), geometry.dh(), strict=True):
        theta = math.radians(qi)
        ct, st = math.cos(theta), math.sin(theta)
        ca, sa = _TWIST[alpha]
        entries += (ct, -st * ca, st * sa, a * ct, st, ct * ca, -ct * sa, a * st)
        entries += (0.0, sa, ca, d, 0.0, 0.0, 0.0, 1.0)
    out = [_EYE4]
    m = _EYE4
    for link in np.fromiter(entries, np.float64, 96).reshape(6, 4, 4):
        m = m @ link
        out.append(m)
    for m in out[1:]:
        m.flags.writeable = False
    return tuple(out)


def forward(q_deg: JointsLike, geometry: PumaGeometry = PUMA560_LEE) -> Transform:
    """Joint angles (deg) to the end-frame transform (mm): the protocol's "solve backwards"."""
    return Transform._trusted(_frames(_as_joints(q_deg), geometry)[-1])


#: The top three rows of a homogeneous transform as plain floats: (R | p).
Rows34 = tuple[tuple[float, float, float, float], ...]


def forward_rows(q_deg: Sequence[float], geometry: PumaGeometry = PUMA560_LEE) -> Rows34:
    """:func:`forward` without numpy, for callers that need one pose fast and no :class:`Transform`
    (a capture's hand picture): the same DH chain in plain floats.  The angles are not validated (pass
    six finite floats).  It agrees with :func:`forward` to rounding (the products are summed in another
    order than numpy's matmul), which a property test checks.
    """
    # Start from link 1 (the product with the identity is exact) and compose (R | p) <- (R | p)(Ra | pa).
    r00, r01, r02, p0, r10, r11, r12, p1, r20, r21, r22, p2 = _link_rows(q_deg[0], *_DH1)
    for qi, (alpha, a, d) in zip(q_deg[1:6], geometry.dh()[1:], strict=True):
        a00, a01, a02, a03, a10, a11, a12, a13, a20, a21, a22, a23 = _link_rows(qi, alpha, a, d)
        r00, r01, r02, p0 = (
            r00 * a00 + r01 * a10 + r02 * a20,
            r00 * a01 + r01 * a11 + r02 * a21,
            r00 * a02 + r01 * a12 + r02 * a22,
            r00 * a03 + r01 * a13 + r02 * a23 + p0,
        )
        r10, r11, r12, p1 = (
            r10 * a00 + r11 * a10 + r12 * a20,
            r10 * a01 + r11 * a11 + r12 * a21,
            r10 * a02 + r11 * a12 + r12 * a22,
            r10 * a03 + r11 * a13 + r12 * a23 + p1,
        )
        r20, r21, r22, p2 = (
            r20 * a00 + r21 * a10 + r22 * a20,
            r20 * a01 + r21 * a11 + r22 * a21,
            r20 * a02 + r21 * a12 + r22 * a22,
            r20 * a03 + r21 * a13 + r22 * a23 + p2,
        )
    return ((r00, r01, r02, p0), (r10, r11, r12, p1), (r20, r21, r22, p2))


_DH1 = (-90.0, 0.0, 0.0)  # link 1's row of every PumaGeometry.dh()


def _link_rows(theta_deg: float, alpha_deg: float, a: float, d: float) -> tuple[float, ...]:
    """The top three rows of link ``i``'s A_i (as in :func:`_frames_of`), flat."""
    theta = math.radians(theta_deg)
    ct, st = math.cos(theta), math.sin(theta)
    ca, sa = _TWIST[alpha_deg]
    return (ct, -st * ca, st * sa, a * ct, st, ct * ca, -ct * sa, a * st, 0.0, sa, ca, d)


def jacobian(
    q_deg: JointsLike, geometry: PumaGeometry = PUMA560_LEE, *, frame: Literal["world", "tool"] = "world"
) -> Matrix:
    """Geometric Jacobian (6x6) of the end frame at ``q_deg``, in API units.

    Rows are (vx, vy, vz) in mm/s then (ωx, ωy, ωz) in deg/s, for joint rates in deg/s; so the upper
    block is mm per degree and the lower block is dimensionless.  ``frame="world"`` expresses both
    vectors in base coordinates; ``frame="tool"`` in end-frame coordinates (what a wrist-mounted force
    sensor sees).  The reference point is always the end-frame origin.
    """
    frames = _frames(_as_joints(q_deg), geometry)
    _, _, _, px, _, _, _, py, _, _, _, pz, *_ = frames[6].ravel().tolist()
    k = math.pi / 180.0
    columns = []
    for f in frames[:6]:
        # z x r, r = p - o, in plain floats: the same operations (so the same bits) as numpy's
        _, _, z0, o0, _, _, z1, o1, _, _, z2, o2, *_ = f.ravel().tolist()
        r0, r1, r2 = px - o0, py - o1, pz - o2
        linear = ((z1 * r2 - z2 * r1) * k, (z2 * r0 - z0 * r2) * k, (z0 * r1 - z1 * r0) * k)
        columns.append((*linear, z0, z1, z2))
    jac = np.array(list(zip(*columns, strict=True)))
    if frame == "tool":
        rt = frames[-1][:3, :3].T
        jac[:3] = rt @ jac[:3]
        jac[3:] = rt @ jac[3:]
    elif frame != "world":
        raise ValueError(f"frame must be 'world' or 'tool', got {frame!r}")
    return jac


# ------------------------------------------------------------------------------------------ inverse
@dataclass(frozen=True)
class Solution:
    """One joint-angle solution (deg) and its VAL arm configuration.

    ``lefty``: the wrist centre lies on the +x side of link 1 (Lee's LEFT arm: raising J2 alone lowers
    the wrist).  ``above``: the elbow is above the shoulder-to-wrist line.  ``flip``: J5 < 0; this is
    VAL-II's FLIP as we recall it (unconfirmed); roboticstoolbox's n/f letters are the other way round
    for the same angles.
    """

    q: Joints
    lefty: bool
    above: bool
    flip: bool
    singular: bool = False
    """The wrist was singular (J5 ≈ 0): J4 was held at the reference value (or the in-range angle
    nearest it), and ``flip`` only follows the sign of the fitted J5, which is noise there."""
    out_of_range: tuple[int, ...] = field(default=())
    """Joints (1-based) of ``q`` outside the limits the solution was computed against."""

    @property
    def config(self) -> str:
        """VAL's configuration words, e.g. ``"RIGHTY ABOVE NOFLIP"``."""
        return " ".join(
            (
                "LEFTY" if self.lefty else "RIGHTY",
                "ABOVE" if self.above else "BELOW",
                "FLIP" if self.flip else "NOFLIP",
            )
        )


def _arm_values(q2: float, q3: float, g: PumaGeometry) -> tuple[float, float]:
    """(u, e): u = wrist reach along link 1's x axis, e = signed elbow bend term."""
    c2 = math.cos(q2)
    c23, s23 = math.cos(q2 + q3), math.sin(q2 + q3)
    u = g.a2 * c2 - g.a3 * c23 + g.d4 * s23
    e = -g.a3 * math.sin(q3) - g.d4 * math.cos(q3)
    return u, e


def configuration(q_deg: JointsLike, geometry: PumaGeometry = PUMA560_LEE) -> tuple[bool, bool, bool]:
    """(lefty, above, flip) of joint angles, with the meanings of :class:`Solution`."""
    q_deg = _as_joints(q_deg)
    u, e = _arm_values(math.radians(q_deg[1]), math.radians(q_deg[2]), geometry)
    return u > 0.0, (u > 0.0) == (e > 0.0), q_deg[4] < 0.0


def _wrist(
    r36: Rows, q4_ref: float, tol_deg: float, limits: JointLimits | None
) -> tuple[list[tuple[float, float, float]], bool]:
    """(θ4, θ5, θ6) in degrees with R36 = Rz(θ4)·Ry(θ5)·Rz(θ6): the noflip (θ5 ≥ 0) then flip solution.

    At the singularity (θ5 within ``tol_deg`` of 0° or 180°) only θ4 ± θ6 is defined, so θ4 is held at
    ``q4_ref`` (brought into range, see :func:`_singular_j4`) and the one solution is returned; θ5 and θ6
    are then fitted to Rz(−θ4)·R36, so a tilt that happens to lie in the held J4 plane is still
    reproduced exactly.
    """
    s5 = math.hypot(r36[0][2], r36[1][2])
    t5 = math.degrees(math.atan2(s5, r36[2][2]))
    if t5 <= tol_deg or t5 >= 180.0 - tol_deg:
        if limits is None:
            return [(q4_ref, *_held_wrist(r36, q4_ref))], True
        q4 = min(max(q4_ref, limits.lower[3]), limits.upper[3])
        fit5, fit6 = _held_wrist(r36, q4)
        # J6 follows J4: J6 ≡ c + sign·J4 (mod 360), J4 + J6 kept near θ5 = 0, J4 − J6 near 180°.  With
        # θ5 off 0 the fitted c drifts with the held J4 (up to ~1e-8° for θ5 at the tolerance): the first
        # search allows for that, the second measures c again at its J4, so that a J4 which J6's range
        # pins to one angle is found to LIMIT_TOL_DEG.
        sign = -1.0 if t5 <= tol_deg else 1.0
        for slack in (_SINGULAR_DRIFT_DEG, LIMIT_TOL_DEG):
            better = _singular_j4(q4_ref, fit6 - sign * q4, sign, limits, slack)
            if better != q4:
                q4 = better
                fit5, fit6 = _held_wrist(r36, q4)
        return [(q4, fit5, fit6)], True
    t4 = math.degrees(math.atan2(r36[1][2], r36[0][2]))
    t6 = math.degrees(math.atan2(r36[2][1], -r36[2][0]))
    return [(t4, t5, t6), (t4 + 180.0, -t5, t6 + 180.0)], False


def _held_wrist(r36: Rows, q4: float) -> tuple[float, float]:
    """(θ5, θ6) in degrees fitted to Rz(−θ4)·R36 for the held θ4 = ``q4``."""
    c4, s4 = math.cos(math.radians(q4)), math.sin(math.radians(q4))
    # held = Rz(−θ4)·R36 ≈ Ry(θ5)·Rz(θ6); only the entries used below
    h00 = c4 * r36[0][0] + s4 * r36[1][0]
    h02 = c4 * r36[0][2] + s4 * r36[1][2]
    h10 = -s4 * r36[0][0] + c4 * r36[1][0]
    h20, h22 = r36[2][0], r36[2][2]
    fit5 = math.atan2(h02, h22)
    c5, s5 = math.cos(fit5), math.sin(fit5)
    # Rz(θ6) ≈ Ry(−θ5)·held: its first column is (c5·h00 − s5·h20, h10, ...)
    fit6 = math.atan2(h10, c5 * h00 - s5 * h20)
    return math.degrees(fit5), math.degrees(fit6)


#: Slack (deg) of the first search for a singular J4 that leaves J6 in range: well above the drift of the
#: fitted J4 ± J6 with the held J4 (see :func:`_wrist`).
_SINGULAR_DRIFT_DEG = 1e-6


def _singular_j4(q4_ref: float, c: float, sign: float, limits: JointLimits, slack: float) -> float:
    """J4 at the wrist singularity: the angle nearest ``q4_ref`` inside J4's range that leaves J6
    (≡ ``c`` + ``sign``·J4 mod 360) an angle inside J6's range, to within ``slack``.  Holding J4 at the
    reference itself would break J4's limit whenever the reference does (e.g. the current angles just
    past a limit), though J6 can take up the difference.  With no such angle (J6's range under 360° and
    J4's too narrow to help) J4's range alone decides, and J6's limit is reported."""
    lo4, hi4 = limits.lower[3], limits.upper[3]
    clamped = min(max(q4_ref, lo4), hi4)
    lo6, hi6 = limits.lower[5], limits.upper[5]
    width = hi6 - lo6
    if width >= 360.0:  # every J4 leaves J6 an angle in range (the PUMA's J6 has 532°)
        return clamped
    # lo6 ≤ c + sign·J4 + 360k ≤ hi6  ⇔  J4 ∈ [start + 360k, start + width + 360k]
    start = c - hi6 if sign < 0.0 else lo6 - c
    best: float | None = None
    k_min = math.ceil((lo4 - slack - start - width) / 360.0)
    k_max = math.floor((hi4 + slack - start) / 360.0)
    for k in range(k_min, k_max + 1):
        low, high = max(lo4, start + 360.0 * k), min(hi4, start + width + 360.0 * k)
        if low > high + slack:  # with the slack, ranges that meet at one angle still do
            continue
        x = min(max(min(max(q4_ref, low), high), lo4), hi4)
        if best is None or abs(x - q4_ref) < abs(best - q4_ref):
            best = x
    return clamped if best is None else best


class _Base(NamedTuple):
    """One configuration's solution with every angle wrapped into (−180, 180]."""

    q: Joints
    lefty: bool
    above: bool
    flip: bool
    singular: bool


class _Arm(NamedTuple):
    """Joints 1-3 of one arm configuration (wrapped, deg) and the rows of R03ᵀ."""

    q: tuple[float, float, float]
    lefty: bool
    above: bool
    r03t: tuple[tuple[float, float, float], ...]


def _arms(
    pose: Transform | Matrix, g: PumaGeometry, ref: Joints, limits: JointLimits | None
) -> tuple[Rows, list[_Arm]]:
    """The rotation of ``pose`` and its four arm solutions (righty before lefty, above before below), in
    plain floats: this runs at every servo cycle of a straight-line move, where numpy's per-call cost on
    3x3 matrices would dominate.  Raises :class:`Unreachable` when the wrist centre is out of reach.

    With the wrist centre on the J1 axis (only with d2 = 0) J1 is free: it is held at ``ref[0]``,
    brought into J1's range when ``limits`` are given."""
    m = (pose.matrix if isinstance(pose, Transform) else np.asarray(pose, dtype=np.float64)).tolist()
    r = (m[0][:3], m[1][:3], m[2][:3])
    px, py, pz = (m[i][3] - g.d6 * m[i][2] for i in range(3))  # the wrist centre p − d6·a

    radial = math.hypot(px, py)
    if radial < abs(g.d2) - REACH_TOL_MM:
        raise Unreachable(
            f"the wrist centre is {radial:.6g} mm from the J1 axis, "
            f"inside the {abs(g.d2):.6g} mm shoulder offset"
        )
    u_abs = math.sqrt(max(radial * radial - g.d2 * g.d2, 0.0))
    forearm = math.hypot(g.a3, g.d4)
    reach = math.hypot(u_abs, pz)  # shoulder (J2 axis) to wrist centre, the same for both arms
    if reach > g.a2 + forearm + REACH_TOL_MM:
        raise Unreachable(
            f"the wrist centre is {reach:.6g} mm from the shoulder, beyond the {g.a2 + forearm:.6g} mm reach"
        )
    if reach < abs(g.a2 - forearm) - REACH_TOL_MM:
        raise Unreachable(
            f"the wrist centre is {reach:.6g} mm from the shoulder, closer than {abs(g.a2 - forearm):.6g} mm"
        )
    sin_elbow = (reach * reach - g.a2 * g.a2 - forearm * forearm) / (2.0 * g.a2 * forearm)
    beta = math.asin(min(1.0, max(-1.0, sin_elbow)))
    phi = math.atan2(g.a3, g.d4)

    # The two elbows (q3) and what depends on them alone: (q3, b_x, b_y, e > 0), where
    # e = −a3·sin q3 − d4·cos q3 = −|forearm|·cos(q3 − φ) is the elbow bend term of _arm_values.
    elbows = []
    for q3 in (phi + beta, phi + math.pi - beta):
        c3, s3 = math.cos(q3), math.sin(q3)
        b_y = -g.a3 * s3 - g.d4 * c3
        elbows.append((q3, g.a2 - g.a3 * c3 + g.d4 * s3, b_y, b_y > 0.0))
    q1_ref = ref[0] if limits is None else min(max(ref[0], limits.lower[0]), limits.upper[0])
    arms: list[_Arm] = []
    for lefty in (False, True):
        u = u_abs if lefty else -u_abs
        on_axis = radial == 0.0 and u == 0.0
        q1 = math.radians(q1_ref) if on_axis else math.atan2(py, px) - math.atan2(g.d2, u)
        c1, s1 = math.cos(q1), math.sin(q1)
        q1_deg = wrap_deg(math.degrees(q1))
        # above first: above when sign(u) == sign(e) (lefty: e > 0); b_y is e
        for q3, b_x, b_y, bent in sorted(elbows, key=lambda el: el[3] != lefty):
            q2 = math.atan2(-pz, u) - math.atan2(b_y, b_x)
            # R03 = Rz(q1)·Rx(−90°)·Rz(q2 + q3)·Rx(90°); its columns are the rows of R03ᵀ
            c23, s23 = math.cos(q2 + q3), math.sin(q2 + q3)
            r03t = ((c1 * c23, s1 * c23, -s23), (-s1, c1, 0.0), (c1 * s23, s1 * s23, c23))
            q = (q1_deg, wrap_deg(math.degrees(q2)), wrap_deg(math.degrees(q3)))
            arms.append(_Arm(q, lefty, lefty == bent, r03t))
    return r, arms


def _wrists(
    arm: _Arm, r: Rows, q4_ref: float, wrist_tol_deg: float, limits: JointLimits | None
) -> list[_Base]:
    """The solutions of one arm configuration: noflip then flip (one solution at the singularity)."""
    r36 = [[a[0] * r[0][j] + a[1] * r[1][j] + a[2] * r[2][j] for j in range(3)] for a in arm.r03t]
    wrists, singular = _wrist(r36, q4_ref, wrist_tol_deg, limits)
    return [
        _Base((*arm.q, wrap_deg(t4), wrap_deg(t5), wrap_deg(t6)), arm.lefty, arm.above, t5 < 0.0, singular)
        for t4, t5, t6 in wrists
    ]


def inverse_all(
    pose: Transform,
    geometry: PumaGeometry = PUMA560_LEE,
    limits: JointLimits | None = UNIMATION_LIMITS,
    *,
    current: JointsLike | None = None,
    wrist_tol_deg: float = WRIST_SINGULAR_DEG,
) -> list[Solution]:
    """Every closed-form solution of ``pose``: 8 configurations, and their in-range ±360° variants.

    Order: righty before lefty, above before below, noflip before flip.  Each configuration first gives
    its base solution with every angle wrapped into (−180, 180], whether or not it is in range; then,
    when ``limits`` is given, every other angle-equivalent vector (shifts by multiples of 360° per joint)
    that lies wholly inside the limits.  That matters for J6 (532° of travel) and for J2 and J3, whose
    ranges extend past ±180°.  ``out_of_range`` is filled against ``limits``.

    At a wrist singularity (J5 within ``wrist_tol_deg`` of 0) flip and noflip coincide: one solution per
    arm/elbow pair, with J4 = ``current[3]`` (0 without ``current``) and J6 taking the rest; with
    ``limits``, a reference outside J4's range gives way to the in-range J4 nearest it (that leaves J6 an
    in-range angle), J4 + J6 kept.  If the wrist centre is on the J1 axis (possible only with d2 = 0),
    J1 = ``current[0]``, likewise brought into range.

    Raises :class:`Unreachable` when the wrist centre is out of the workspace.
    """
    ref = _as_joints(current) if current is not None else (0.0,) * 6
    r, arms = _arms(pose, geometry, ref, limits)
    out: list[Solution] = []
    for arm in arms:
        for b in _wrists(arm, r, ref[3], wrist_tol_deg, limits):
            out.extend(_with_variants(b.q, b.lefty, b.above, b.flip, b.singular, limits))
    return out


def _with_variants(
    q: tuple[float, ...], lefty: bool, above: bool, flip: bool, singular: bool, limits: JointLimits | None
) -> list[Solution]:
    def make(v: Sequence[float]) -> Solution:
        bad = tuple(limits.violations(v)) if limits is not None else ()
        return Solution(_joints(v), lefty, above, flip, singular, bad)

    base = make(q)
    if limits is None:
        return [base]
    options = [limits.representations(j, v) for j, v in enumerate(q, start=1)]
    variants = [make(v) for v in itertools.product(*options) if v != q]
    return [base, *variants]


def _joints(v: Sequence[float]) -> Joints:
    return (float(v[0]), float(v[1]), float(v[2]), float(v[3]), float(v[4]), float(v[5]))


def _distance(q: Sequence[float], current: Sequence[float], weights: Sequence[float]) -> float:
    return sum(w * (a - b) ** 2 for a, b, w in zip(q, current, weights, strict=True))


def nearest_solution(
    pose: Transform | Matrix,
    current: JointsLike,
    geometry: PumaGeometry = PUMA560_LEE,
    limits: JointLimits = UNIMATION_LIMITS,
    *,
    weights: Sequence[float] = (1.0, 1.0, 1.0, 1.0, 1.0, 1.0),
    wrist_tol_deg: float = WRIST_SINGULAR_DEG,
) -> Solution:
    """The in-range solution nearest ``current`` (see :func:`inverse_nearest`), with its configuration.

    ``pose`` may also be a 4x4 matrix, taken as is (no checks: for poses computed in the simulator,
    such as the points of a straight line, which are solved at every servo cycle).
    """
    current = _as_joints(current)
    if len(weights) != 6:
        raise ValueError("weights needs one value per joint")
    # The distance is a sum over joints and the limits hold joint by joint, so each configuration's
    # nearest in-range ±360° variant is found joint by joint, and with weights >= 0 a configuration whose
    # arm joints alone are already farther than the best so far needs no wrist: the same answer as the
    # least of inverse_all's enumeration (ties too: the first in its order wins) for a fraction of the
    # work, which matters at every servo cycle of a straight-line move.
    r, arms = _arms(pose, geometry, current, limits)
    near = _Nearest(current, weights, limits)
    scored: list[tuple[float, int, list[float]]] = []
    for index, arm in enumerate(arms):
        found = near.part(arm.q, 0, 0.0, math.inf)
        if found is not None:
            scored.append((found[1], index, found[0]))
    if near.prune:
        scored.sort(key=lambda e: (e[0], e[1]))
    best: Solution | None = None
    best_key = (math.inf, 0, 0)
    for d_arm, index, head in scored:
        if near.prune and d_arm > best_key[0]:
            break  # this arm and every later one are farther than the best
        for k, b in enumerate(_wrists(arms[index], r, current[3], wrist_tol_deg, limits)):
            found = near.part(b.q[3:], 3, d_arm, best_key[0] if near.prune else math.inf)
            # found[1] is _distance(q, current, weights): the same terms summed in the same order
            if found is not None and (found[1], index, k) < best_key:
                q = _joints(head + found[0])
                best, best_key = Solution(q, b.lefty, b.above, b.flip, b.singular), (found[1], index, k)
    if best is not None:
        return best
    if not isinstance(pose, Transform):
        pose = Transform(pose)
    solutions = inverse_all(pose, geometry, limits, current=current, wrist_tol_deg=wrist_tol_deg)

    def badness(s: Solution) -> tuple[int, float]:
        return len(_unfixable(s.q, limits)), _distance(s.q, current, weights)

    worst = min(solutions, key=badness)
    raise OutOfRange(_unfixable(worst.q, limits), solutions)


class _Nearest:
    """Joint-by-joint choice of the in-range angles nearest ``current`` (for :func:`nearest_solution`)."""

    def __init__(self, current: Joints, weights: Sequence[float], limits: JointLimits) -> None:
        self.current = current
        self.weights = tuple(float(w) for w in weights)
        self.low = tuple(lo - LIMIT_TOL_DEG for lo in limits.lower)
        self.high = tuple(hi + LIMIT_TOL_DEG for hi in limits.upper)
        self.prune = all(w >= 0.0 for w in self.weights)
        """Every term is >= 0, so partial sums only grow and may be cut off."""

    def part(
        self, values: Sequence[float], first: int, distance: float, bound: float
    ) -> tuple[list[float], float] | None:
        """The nearest in-range angles for ``values`` (joints ``first``, ``first`` + 1, ... 0-based) and
        ``distance`` plus their terms; None when a joint has no such angle or the sum passes ``bound``."""
        chosen: list[float] = []
        for j, v in enumerate(values, start=first):
            c, w = self.current[j], self.weights[j]
            x = _nearest_in_range(v, c, w, self.low[j], self.high[j])
            if x is None:
                return None
            distance += w * (x - c) ** 2
            if distance > bound:
                return None
            chosen.append(x)
        return chosen, distance


def _nearest_in_range(angle: float, near: float, weight: float, low: float, high: float) -> float | None:
    """The angle ≡ ``angle`` (mod 360) in [low, high] minimising ``weight·(x − near)²``, None if none:
    the first such angle of :meth:`JointLimits.representations` (bounds already widened by its
    tolerance), found without listing them."""
    k_min = math.ceil((low - angle) / 360.0)
    k_max = math.floor((high - angle) / 360.0)
    if k_min > k_max:
        return None
    if not weight > 0.0:  # the farthest, or any: rare enough to list them all, in that order
        return min((angle + 360.0 * i for i in sorted(range(k_min, k_max + 1), key=abs)),
                   key=lambda x: weight * (x - near) ** 2)  # fmt: skip
    # The nearest is the k-th or the (k+1)-th, clamped; on a tie, the one nearer ``angle``.
    k = math.floor((near - angle) / 360.0)
    k0, k1 = min(max(k, k_min), k_max), min(max(k + 1, k_min), k_max)
    x0 = angle + 360.0 * k0
    if k1 == k0:
        return x0
    x1 = angle + 360.0 * k1
    d0, d1 = weight * (x0 - near) ** 2, weight * (x1 - near) ** 2
    return x1 if d1 < d0 or (d1 == d0 and abs(k1) < abs(k0)) else x0


def _unfixable(q: Sequence[float], limits: JointLimits) -> list[int]:
    """Joints with no 360°-equivalent angle inside their range."""
    return [j for j, v in enumerate(q, start=1) if not limits.representations(j, v)]


def inverse_nearest(
    pose: Transform,
    current: JointsLike,
    geometry: PumaGeometry = PUMA560_LEE,
    limits: JointLimits = UNIMATION_LIMITS,
    *,
    weights: Sequence[float] = (1.0, 1.0, 1.0, 1.0, 1.0, 1.0),
    wrist_tol_deg: float = WRIST_SINGULAR_DEG,
) -> Joints:
    """Transform to joint angles (deg): the protocol's "solve forwards".

    Among all solutions and their ±360° variants that respect ``limits``, return the one with the least
    weighted squared distance Σ w_j (q_j − current_j)² to ``current``; so the arm keeps its present
    configuration whenever it can.  At the wrist singularity J4 stays at ``current[3]``, or moves to the
    nearest angle in its range when ``current[3]`` is outside it, and J6 keeps J4 + J6.

    Raises :class:`Unreachable` when no solution exists, :class:`OutOfRange` when every solution breaks
    a limit (both TOR on the wire).
    """
    return nearest_solution(pose, current, geometry, limits, weights=weights, wrist_tol_deg=wrist_tol_deg).q
