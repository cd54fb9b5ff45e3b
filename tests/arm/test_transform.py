"""Transform algebra, the protocol's 12-float layout, and VAL's O/A/T angles (model H1)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from manip.arm.oat import (
    OAT_SINGULAR_TOL_DEG,
    add_increment,
    apply_increment,
    rotation_from_oat,
    transform_from_xyzoat,
    wrap_deg,
    xyzoat_from_transform,
)
from manip.arm.transform import Transform, rotation_angle_deg

FAST = settings(max_examples=150, deadline=None)

angles = st.floats(-180.0, 180.0, allow_nan=False)
coords = st.floats(-2000.0, 2000.0, allow_nan=False)


@st.composite
def transforms(draw: st.DrawFn) -> Transform:
    """Random rigid transforms: a unit quaternion (uniform enough) and a translation."""
    quat = np.array([draw(st.floats(-1.0, 1.0, allow_nan=False)) for _ in range(4)])
    norm = float(np.linalg.norm(quat))
    if norm < 1e-3:
        quat, norm = np.array([1.0, 0.0, 0.0, 0.0]), 1.0
    w, x, y, z = quat / norm
    r = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    return Transform.from_rotation_translation(r, [draw(coords) for _ in range(3)])


# ------------------------------------------------------------------------------------ Transform
def test_identity_and_elementary_rotations_are_right_handed() -> None:
    assert np.array_equal(Transform.identity().matrix, np.eye(4))
    assert np.allclose(Transform.rot_z(90).apply([1, 0, 0]), [0, 1, 0], atol=1e-15)
    assert np.allclose(Transform.rot_x(90).apply([0, 1, 0]), [0, 0, 1], atol=1e-15)
    assert np.allclose(Transform.rot_y(90).apply([0, 0, 1]), [1, 0, 0], atol=1e-15)
    assert np.allclose(Transform.trans(1, 2, 3).apply([1, 1, 1]), [2, 3, 4])


def test_n_o_a_p_are_the_columns() -> None:
    t = Transform.trans(10, 20, 30) @ Transform.rot_x(90)
    assert np.allclose(t.n, [1, 0, 0]) and np.allclose(t.o, [0, 0, 1]) and np.allclose(t.a, [0, -1, 0])
    assert np.allclose(t.p, [10, 20, 30])


def test_to_floats_is_column_major_n_o_a_p() -> None:
    t = Transform.trans(10, 20, 30) @ Transform.rot_z(90)
    expected = (0.0, 1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 10.0, 20.0, 30.0)
    assert np.allclose(t.to_floats(), expected, atol=1e-15)
    assert all(type(x) is float for x in t.to_floats())


@FAST
@given(transforms())
def test_floats_round_trip_exactly(t: Transform) -> None:
    assert Transform.from_floats(t.to_floats()) == t


@FAST
@given(transforms(), transforms(), transforms())
def test_composition_and_inverse(a: Transform, b: Transform, c: Transform) -> None:
    assert ((a @ b) @ c).almost_equal(a @ (b @ c), 1e-9)
    assert (a @ a.inverse()).almost_equal(Transform.identity(), 1e-9)
    assert (a.inverse() @ a).almost_equal(Transform.identity(), 1e-9)
    assert np.allclose(a.inverse().matrix, np.linalg.inv(a.matrix), atol=1e-9)


def test_from_floats_rejects_bad_data() -> None:
    good = list(Transform.rot_z(30).to_floats())
    with pytest.raises(ValueError, match="12 floats"):
        Transform.from_floats(good[:11])
    with pytest.raises(ValueError, match="finite"):
        Transform.from_floats([*good[:11], math.nan])
    scaled = [2.0 * x for x in good[:9]] + good[9:]
    with pytest.raises(ValueError, match="not a rotation"):
        Transform.from_floats(scaled)
    mirrored = [-x for x in good[:3]] + good[3:]  # N = −(O × A): left-handed
    with pytest.raises(ValueError, match="not a rotation"):
        Transform.from_floats(mirrored)


def test_from_floats_accepts_single_precision_noise_and_can_clean_it() -> None:
    exact = Transform.rot_x(20) @ Transform.rot_z(35)
    noisy = [float(np.float32(x)) for x in exact.to_floats()]
    assert not Transform.from_floats(noisy).is_rigid(1e-12)
    cleaned = Transform.from_floats(noisy, orthonormalise=True)
    assert cleaned.is_rigid(1e-14)
    assert cleaned.almost_equal(exact, 1e-5)
    with pytest.raises(ValueError):
        Transform.from_floats(noisy, tol=1e-12)


def test_constructor_validation_and_immutability() -> None:
    with pytest.raises(ValueError, match="4x4"):
        Transform(np.eye(3))
    bad = np.eye(4)
    bad[3, 0] = 1.0
    with pytest.raises(ValueError, match="bottom row"):
        Transform(bad)
    t = Transform.trans(1, 2, 3)
    with pytest.raises(ValueError):
        t.matrix[0, 3] = 5.0
    with pytest.raises(AttributeError):
        t._m = np.eye(4)
    source = np.eye(4)
    u = Transform(source)
    source[0, 3] = 7.0
    assert u.p[0] == 0.0
    assert hash(Transform.trans(1, 2, 3)) == hash(t) and Transform.trans(1, 2, 3) == t


def test_copy_and_pickle_keep_the_value() -> None:
    import copy
    import pickle

    t = Transform.trans(1, 2, 3) @ Transform.rot_y(10)
    for clone in (copy.copy(t), copy.deepcopy(t), pickle.loads(pickle.dumps(t))):
        assert clone == t and not clone.matrix.flags.writeable


def test_pose_distance() -> None:
    d = Transform.identity().distance(Transform.trans(3, 4, 0) @ Transform.rot_x(30))
    assert d.translation_mm == pytest.approx(5.0) and d.rotation_deg == pytest.approx(30.0)
    assert rotation_angle_deg(Transform.rot_y(179.9999).rotation) == pytest.approx(179.9999, abs=1e-9)
    assert rotation_angle_deg(Transform.rot_z(1e-7).rotation) == pytest.approx(1e-7, rel=1e-6)
    assert not Transform.identity().almost_equal(Transform.rot_z(1e-3), 1e-4)


# ------------------------------------------------------------------------------------ O, A, T
def test_oat_zero_is_val_1977_hand_pointing_minus_y() -> None:
    t = transform_from_xyzoat(0, 0, 0, 0, 0, 0)
    assert np.allclose(t.a, [0, -1, 0]) and np.allclose(t.o, [1, 0, 0]) and np.allclose(t.n, [0, 0, -1])
    assert np.allclose(transform_from_xyzoat(0, 0, 0, 90, 0, 0).a, [1, 0, 0])  # O turns about vertical
    assert np.allclose(transform_from_xyzoat(0, 0, 0, 0, 90, 0).a, [0, 0, -1])  # A = +90: down
    assert np.allclose(transform_from_xyzoat(0, 0, 0, 0, 0, 90).o, [0, 0, 1])  # T = 90: fingers vertical


def test_worked_example_h1() -> None:
    """docs/kinematics.md §2.3: O, A, T = 30, 45, 60."""
    expected = [
        [0.573223, 0.739199, 0.353553],
        [0.739199, -0.280330, -0.612372],
        [-0.353553, 0.612372, -0.707107],
    ]
    t = transform_from_xyzoat(100, 200, 300, 30, 45, 60)
    assert np.allclose(t.rotation, expected, atol=1e-6)
    assert np.allclose(xyzoat_from_transform(t), (100, 200, 300, 30, 45, 60), atol=1e-9)


def test_h1_equals_offset_zyz_euler() -> None:
    for o, a, t in [(30, 45, 60), (-120, 10, 170), (0, -80, -45)]:
        zyz = Transform.rot_z(o - 90) @ Transform.rot_y(a + 90) @ Transform.rot_z(t)
        assert np.allclose(rotation_from_oat(o, a, t), zyz.rotation, atol=1e-15)


def test_singular_cases() -> None:
    down = Transform.rot_x(180)  # hand straight down, fingers along X
    assert np.allclose(xyzoat_from_transform(down), (0, 0, 0, -90, 90, 0), atol=1e-9)
    up = Transform.identity()  # hand straight up
    assert np.allclose(xyzoat_from_transform(up), (0, 0, 0, 90, -90, 0), atol=1e-9)
    for pose in (down, up, Transform.rot_z(37) @ down, Transform.rot_z(-110)):
        for hint in (0.0, 25.0, -170.0):
            x, y, z, o, a, t = xyzoat_from_transform(pose, singular_t=hint)
            assert t == pytest.approx(wrap_deg(hint))
            assert transform_from_xyzoat(x, y, z, o, a, t).almost_equal(pose, 1e-9)


@FAST
@given(coords, coords, coords, angles, st.floats(-89.0, 89.0), angles)
def test_oat_round_trip(x: float, y: float, z: float, o: float, a: float, t: float) -> None:
    back = xyzoat_from_transform(transform_from_xyzoat(x, y, z, o, a, t))
    assert np.allclose(back[:3], (x, y, z), atol=1e-9)
    assert back[4] == pytest.approx(a, abs=1e-9)
    for got, want in ((back[3], o), (back[5], t)):
        assert abs(wrap_deg(got - want)) < 1e-9


@FAST
@given(transforms())
def test_any_rotation_has_oat_angles(pose: Transform) -> None:
    x, y, z, o, a, t = xyzoat_from_transform(pose)
    assert -90.0 <= a <= 90.0 and -180.0 < o <= 180.0 and -180.0 < t <= 180.0
    # Off by at most the tilt below which a pose counts as vertical (the documented bound).
    assert transform_from_xyzoat(x, y, z, o, a, t).almost_equal(pose, OAT_SINGULAR_TOL_DEG)


def test_incremental_move_adds_world_position_and_oat_angles() -> None:
    start = transform_from_xyzoat(100, 200, 300, 30, 45, 60)
    moved = apply_increment(start, 1, -2, 3, 10, -5, 20)
    assert moved.almost_equal(transform_from_xyzoat(101, 198, 303, 40, 40, 80), 1e-9)
    assert add_increment((1, 2, 3, 80, 85, 0), (0, 0, 0, 0, 10, 0))[4] == 95  # A may pass 90


def test_incremental_move_uses_commanded_angles_at_the_singularity() -> None:
    """With the hand straight down only O − T is defined; re-extraction loses the client's split."""
    commanded = (30.0, 90.0, 30.0)
    pose = transform_from_xyzoat(0, 0, 500, *commanded)
    assert np.allclose(xyzoat_from_transform(pose)[3:], (0, 90, 0), atol=1e-9)
    intended = apply_increment(pose, 0, 0, 0, 0, -10, 0, oat=commanded)
    assert intended.almost_equal(transform_from_xyzoat(0, 0, 500, 30, 80, 30), 1e-9)
    naive = apply_increment(pose, 0, 0, 0, 0, -10, 0)
    assert not naive.almost_equal(intended, 1.0)
