"""Rigid transforms as the protocol sees them: millimetres, degrees, and 12 floats N O A P.

:class:`Transform` wraps a read-only 4x4 float64 homogeneous matrix, so a pose can be passed around,
hashed and compared without anyone mutating it behind the arm model's back.  The protocol's "Here",
"Move" and "Solve" packets carry the 3x4 part in column-major order (Nx Ny Nz Ox Oy Oz Ax Ay Az Px Py
Pz, Paul's notation: n = normal, o = orientation, a = approach, p = position); :meth:`Transform.to_floats`
and :meth:`Transform.from_floats` are the only places that know that order.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple, SupportsFloat

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["FLOAT_ROTATION_TOL", "PoseDistance", "Transform", "rotation_angle_deg"]

Matrix = NDArray[np.float64]

#: Default tolerance of :meth:`Transform.from_floats` on ``max|RᵀR − I|`` and ``|det R − 1|``.  PDP-11
#: single floats carry 24 bits (relative error ~6e-8), and a Lisp Machine client may have built the matrix
#: in single precision, so anything much tighter would reject honest data.
FLOAT_ROTATION_TOL = 1e-4


class PoseDistance(NamedTuple):
    """How far apart two poses are: translation in mm and the angle of the relative rotation in degrees."""

    translation_mm: float
    rotation_deg: float


def _frozen(m: Matrix) -> Matrix:
    m.flags.writeable = False
    return m


def rotation_angle_deg(r: ArrayLike) -> float:
    """Angle (deg, in [0, 180]) of a 3x3 rotation, accurate near 0° and 180° (atan2, not acos)."""
    m = np.asarray(r, dtype=np.float64)
    sin2 = math.hypot(m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1])
    cos2 = float(m[0, 0] + m[1, 1] + m[2, 2]) - 1.0
    return math.degrees(math.atan2(sin2, cos2))


def _rotation_error(r: Matrix) -> float:
    """Largest deviation of ``r`` from a proper rotation (orthonormality and det = +1)."""
    ortho = float(np.max(np.abs(r.T @ r - np.eye(3))))
    return max(ortho, abs(float(np.linalg.det(r)) - 1.0))


def _nearest_rotation(r: Matrix) -> Matrix:
    """The rotation closest to ``r`` in the Frobenius norm (polar decomposition via SVD)."""
    u, _, vt = np.linalg.svd(r)
    d = np.sign(np.linalg.det(u @ vt))
    out: Matrix = u @ np.diag([1.0, 1.0, d]) @ vt
    return out


class Transform:
    """An immutable 4x4 homogeneous rigid transform (mm); compose with ``@``.

    The constructor checks shape, finiteness and the bottom row but trusts the 3x3 part, because internal
    products of rotations stay orthonormal to rounding; data from outside goes through
    :meth:`from_floats`, which checks it.
    """

    __slots__ = ("_m",)
    _m: Matrix

    def __init__(self, matrix: ArrayLike) -> None:
        m = np.array(matrix, dtype=np.float64)  # always a private copy
        if m.shape != (4, 4):
            raise ValueError(f"a transform is a 4x4 matrix, got shape {m.shape}")
        if not np.isfinite(m).all():
            raise ValueError("a transform must contain only finite numbers")
        if m[3].tolist() != [0.0, 0.0, 0.0, 1.0]:
            raise ValueError(f"the bottom row of a homogeneous transform is 0 0 0 1, got {m[3].tolist()}")
        object.__setattr__(self, "_m", _frozen(m))

    @classmethod
    def _trusted(cls, matrix: Matrix) -> Transform:
        """A transform sharing ``matrix``, unchecked: for the arm model's own products, which are finite
        with an exact bottom row by construction, and already read-only (this does not copy)."""
        if matrix.flags.writeable:
            raise ValueError("Transform._trusted needs a read-only matrix")
        t = object.__new__(cls)
        object.__setattr__(t, "_m", matrix)
        return t

    def __setattr__(self, name: str, value: object) -> None:
        raise AttributeError("Transform is immutable")

    def __reduce__(self) -> tuple[type[Transform], tuple[Matrix]]:
        # copy and pickle would otherwise restore the slot through the blocked __setattr__
        return (Transform, (np.array(self._m),))

    # ---------------------------------------------------------------- constructors
    @classmethod
    def identity(cls) -> Transform:
        return cls(np.eye(4))

    @classmethod
    def from_rotation_translation(
        cls, rotation: ArrayLike, translation: ArrayLike = (0.0, 0.0, 0.0)
    ) -> Transform:
        """Build from a 3x3 rotation and a translation (mm); the rotation is not checked."""
        r = np.asarray(rotation, dtype=np.float64)
        p = np.asarray(translation, dtype=np.float64)
        if r.shape != (3, 3) or p.shape != (3,):
            raise ValueError(f"expected a 3x3 rotation and a 3-vector, got {r.shape} and {p.shape}")
        m = np.eye(4)
        m[:3, :3] = r
        m[:3, 3] = p
        return cls(m)

    @classmethod
    def trans(cls, x: float, y: float, z: float) -> Transform:
        """Pure translation by (x, y, z) mm."""
        return cls.from_rotation_translation(np.eye(3), (x, y, z))

    @classmethod
    def rot_x(cls, deg: float) -> Transform:
        """Right-handed rotation about x by ``deg`` degrees."""
        c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
        return cls.from_rotation_translation([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])

    @classmethod
    def rot_y(cls, deg: float) -> Transform:
        """Right-handed rotation about y by ``deg`` degrees."""
        c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
        return cls.from_rotation_translation([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])

    @classmethod
    def rot_z(cls, deg: float) -> Transform:
        """Right-handed rotation about z by ``deg`` degrees."""
        c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
        return cls.from_rotation_translation([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    @classmethod
    def from_floats(
        cls,
        values: Sequence[SupportsFloat],
        *,
        tol: float = FLOAT_ROTATION_TOL,
        orthonormalise: bool = False,
    ) -> Transform:
        """Read the protocol's 12 floats Nx Ny Nz Ox Oy Oz Ax Ay Az Px Py Pz (column major).

        Raises ValueError unless there are 12 finite values whose 3x3 part is a proper rotation within
        ``tol``.  With ``orthonormalise`` the accepted rotation is replaced by the nearest exact one, so
        that single-precision noise does not accumulate through later compositions.
        """
        if len(values) != 12:
            raise ValueError(f"a transform is 12 floats (N O A P, column major), got {len(values)}")
        v = np.array([float(x) for x in values], dtype=np.float64)
        if not np.all(np.isfinite(v)):
            raise ValueError("transform floats must be finite")
        cols = v.reshape(4, 3)  # rows of this array are the columns n, o, a, p
        r = cols[:3].T.copy()
        err = _rotation_error(r)
        if err > tol:
            raise ValueError(
                f"the N, O, A columns are not a rotation: deviation {err:.3g} exceeds tolerance {tol:.3g} "
                "(they must be orthonormal and right-handed, N = O x A)"
            )
        if orthonormalise:
            r = _nearest_rotation(r)
        return cls.from_rotation_translation(r, cols[3])

    # ---------------------------------------------------------------- views
    @property
    def matrix(self) -> Matrix:
        """The read-only 4x4 array."""
        return self._m

    @property
    def rotation(self) -> Matrix:
        return self._m[:3, :3]

    @property
    def n(self) -> Matrix:
        """Normal vector (tool x axis)."""
        return self._m[:3, 0]

    @property
    def o(self) -> Matrix:
        """Orientation vector (tool y axis, finger to finger)."""
        return self._m[:3, 1]

    @property
    def a(self) -> Matrix:
        """Approach vector (tool z axis)."""
        return self._m[:3, 2]

    @property
    def p(self) -> Matrix:
        """Position (mm)."""
        return self._m[:3, 3]

    def to_floats(self) -> tuple[float, ...]:
        """The 12 protocol floats Nx Ny Nz Ox Oy Oz Ax Ay Az Px Py Pz (the 3x4 part, column major)."""
        return tuple(float(x) for x in self._m[:3, :].T.reshape(12))

    # ---------------------------------------------------------------- algebra
    def __matmul__(self, other: Transform) -> Transform:
        if not isinstance(other, Transform):
            return NotImplemented
        return Transform(self._m @ other._m)

    def inverse(self) -> Transform:
        """Exact rigid inverse (Rᵀ, −Rᵀp): cheaper and better conditioned than a general matrix inverse."""
        rt = self.rotation.T
        return Transform.from_rotation_translation(rt, -rt @ self.p)

    def apply(self, point: ArrayLike) -> Matrix:
        """Map a point (mm) from this frame's coordinates to the parent's."""
        out: Matrix = self.rotation @ np.asarray(point, dtype=np.float64) + self.p
        return out

    def distance(self, other: Transform) -> PoseDistance:
        """Translation distance (mm) and angle of the relative rotation (deg) between two poses."""
        dp = float(np.linalg.norm(self.p - other.p))
        return PoseDistance(dp, rotation_angle_deg(self.rotation.T @ other.rotation))

    def almost_equal(self, other: Transform, tol: float = 1e-9) -> bool:
        """True when both the translation (mm) and the rotation angle (deg) differ by at most ``tol``."""
        d = self.distance(other)
        return d.translation_mm <= tol and d.rotation_deg <= tol

    def is_rigid(self, tol: float = 1e-9) -> bool:
        """Whether the 3x3 part is a proper rotation within ``tol``."""
        return _rotation_error(np.asarray(self.rotation)) <= tol

    # ---------------------------------------------------------------- value semantics
    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Transform):
            return NotImplemented
        return bool(np.array_equal(self._m, other._m))

    def __hash__(self) -> int:
        return hash(self._m.tobytes())

    def __repr__(self) -> str:
        rows = "; ".join(" ".join(f"{x:.6g}" for x in row) for row in self._m[:3])
        return f"Transform([{rows}])"
