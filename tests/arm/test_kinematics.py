"""PUMA kinematics in the Lee/VAL convention: FK, closed-form IK, limits, errors and the Jacobian."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

from manip.arm.kinematics import (
    LEE_FLANGE_MM,
    PUMA560_CORKE,
    PUMA560_LEE,
    PUMA600,
    READY,
    UNIMATION_LIMITS,
    WRIST_SINGULAR_DEG,
    JointLimits,
    OutOfRange,
    PumaGeometry,
    Unreachable,
    configuration,
    forward,
    forward_rows,
    inverse_all,
    inverse_nearest,
    jacobian,
    joint_mask,
    nearest_solution,
    within_limits,
)
from manip.arm.oat import wrap_deg
from manip.arm.transform import Transform

FAST = settings(max_examples=120, deadline=None)
LEE_FLANGE = PumaGeometry(431.8, 20.32, 149.09, 433.07, LEE_FLANGE_MM, "Lee, flange frame")
GEOMETRIES = (PUMA560_LEE, PUMA560_CORKE, LEE_FLANGE)
RTB_TO_LEE = np.array([0.0, 180.0, 180.0, 0.0, 0.0, 0.0])
PEDESTAL_MM = 671.83


# ---------------------------------------------------------------------------- independent formulations
def _rx(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1]], dtype=float)


def _rz(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=float)


def _tx(a: float) -> np.ndarray:
    m = np.eye(4)
    m[0, 3] = a
    return m


def _tz(d: float) -> np.ndarray:
    m = np.eye(4)
    m[2, 3] = d
    return m


def craig_fk(q: Sequence[float], g: PumaGeometry) -> np.ndarray:
    """Modified DH (Craig), AKB-style table: A_i = Rx(α_{i−1})·Tx(a_{i−1})·Rz(θ_i)·Tz(d_i).

    The shoulder offset is split over joints 2 and 3 as Armstrong-Khatib-Burdick do (243.5 mm and the
    rest), to show the split does not matter.
    """
    rows = [(0, 0, 0), (-90, 0, 243.5), (0, g.a2, g.d2 - 243.5), (90, -g.a3, g.d4), (-90, 0, 0), (90, 0, 0)]
    m = np.eye(4)
    for qi, (alpha, a, d) in zip(q, rows, strict=True):
        m = m @ _rx(alpha) @ _tx(a) @ _rz(qi) @ _tz(d)
    out: np.ndarray = m @ _tz(g.d6)
    return out


def rtb_fk(q: Sequence[float], g: PumaGeometry) -> np.ndarray:
    """roboticstoolbox's standard-DH Puma560 table (no pedestal): A_i = Rz(θ)·Tz(d)·Tx(a)·Rx(α)."""
    rows = [(90, 0, 0), (0, g.a2, 0), (-90, g.a3, g.d2), (90, 0, g.d4), (-90, 0, 0), (0, 0, g.d6)]
    m = np.eye(4)
    for qi, (alpha, a, d) in zip(q, rows, strict=True):
        m = m @ _rz(qi) @ _tz(d) @ _tx(a) @ _rx(alpha)
    return m


# ---------------------------------------------------------------------------- strategies
def _joint(j: int) -> st.SearchStrategy[float]:
    return st.floats(UNIMATION_LIMITS.lower[j], UNIMATION_LIMITS.upper[j], allow_nan=False)


legal_q = st.tuples(*(_joint(j) for j in range(6)))
#: Current angles anywhere, even out of range or a whole turn off (the ±360° choice then matters).
_ANY = st.tuples(*(st.floats(-400.0, 400.0) for _ in range(6)))
#: Legal angles with |J5| ≥ 1°, away from the wrist singularity.
regular_q = st.tuples(
    *(_joint(j) for j in range(4)), st.one_of(st.floats(-100.0, -1.0), st.floats(1.0, 100.0)), _joint(5)
)


def _well_conditioned(q: Sequence[float], g: PumaGeometry) -> bool:
    """Away from the shoulder and elbow singularities, where the arm angles are ill-conditioned."""
    q2, q3 = math.radians(q[1]), math.radians(q[2])
    u = g.a2 * math.cos(q2) - g.a3 * math.cos(q2 + q3) + g.d4 * math.sin(q2 + q3)
    elbow = math.cos(q3 - math.atan2(g.a3, g.d4))
    return abs(u) > 1.0 and abs(elbow) > 1e-3


# ---------------------------------------------------------------------------- forward
def test_ready_points_straight_up() -> None:
    t = forward(READY)
    assert np.allclose(t.p, [-20.32, 149.09, 431.8 + 433.07], atol=1e-9)
    assert np.allclose(t.a, [0, 0, 1], atol=1e-15) and np.allclose(t.rotation, np.eye(3), atol=1e-15)
    flange = forward(READY, LEE_FLANGE)
    assert np.allclose(flange.p, [-20.32, 149.09, 864.87 + 56.25], atol=1e-9)
    assert PUMA600.ready == READY and PUMA600.geometry is PUMA560_LEE


@FAST
@given(st.tuples(*(st.floats(-360.0, 360.0) for _ in range(6))), st.sampled_from(GEOMETRIES))
def test_forward_matches_modified_dh(q: tuple[float, ...], g: PumaGeometry) -> None:
    assert np.allclose(forward(q, g).matrix, craig_fk(q, g), rtol=0.0, atol=1e-9)


@FAST
@given(st.tuples(*(st.floats(-720.0, 720.0) for _ in range(6))), st.sampled_from(GEOMETRIES))
def test_forward_rows_is_forward_without_numpy(q: tuple[float, ...], g: PumaGeometry) -> None:
    # Same chain, products summed in another order: equal to rounding (a few ulps of ~1000 mm).
    rows = forward_rows(q, g)
    assert len(rows) == 3 and all(len(row) == 4 for row in rows)
    assert np.allclose(np.array(rows), forward(q, g).matrix[:3], rtol=0.0, atol=1e-11)


@FAST
@given(st.tuples(*(st.floats(-360.0, 360.0) for _ in range(6))), st.sampled_from(GEOMETRIES))
def test_rtb_convention_maps_exactly(q: tuple[float, ...], g: PumaGeometry) -> None:
    """T_Lee(q + (0, 180, 180, 0, 0, 0)) = Rz(180)·T_RTB(q)·Rz(180)  (docs/kinematics.md §1)."""
    lee = forward(np.array(q) + RTB_TO_LEE, g).matrix
    assert np.allclose(lee, _rz(180) @ rtb_fk(q, g) @ _rz(180), atol=1e-9)


# The chain as first written, one numpy array per link multiplied from the identity, and the Jacobian
# built on it: forward and jacobian must give the same bits (zeros' signs included), because the
# simulated Cougar stores what they compute where the Puma reads it.
def _numpy_link(theta: float, alpha_deg: float, a: float, d: float) -> np.ndarray:
    ct, st = math.cos(theta), math.sin(theta)
    ca, sa = {-90.0: (0.0, -1.0), 0.0: (1.0, 0.0), 90.0: (0.0, 1.0)}[alpha_deg]
    top = [[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st], [0.0, sa, ca, d]]
    return np.array([*top, [0.0, 0.0, 0.0, 1.0]])


def _numpy_frames(q: Sequence[float], g: PumaGeometry) -> list[np.ndarray]:
    out = [np.eye(4)]
    for qi, (alpha, a, d) in zip(q, g.dh(), strict=True):
        out.append(out[-1] @ _numpy_link(math.radians(qi), alpha, a, d))
    return out


def _numpy_jacobian(q: Sequence[float], g: PumaGeometry, frame: str) -> np.ndarray:
    frames = _numpy_frames(q, g)
    p = frames[-1][:3, 3]
    jac = np.empty((6, 6))
    for i in range(6):
        z = frames[i][:3, 2]
        jac[:3, i] = np.cross(z, p - frames[i][:3, 3]) * (math.pi / 180.0)
        jac[3:, i] = z
    if frame == "tool":
        rt = frames[-1][:3, :3].T
        jac[:3] = rt @ jac[:3]
        jac[3:] = rt @ jac[3:]
    return jac


_SPECIAL_ANGLES = st.sampled_from([0.0, -0.0, 90.0, -90.0, 180.0, -180.0, 45.0, 270.0, 1e-300, -1e-300])
_ANY_ANGLE = st.one_of(st.floats(-720.0, 720.0), _SPECIAL_ANGLES, st.floats(-1e6, 1e6))


@FAST
@given(st.tuples(*(_ANY_ANGLE for _ in range(6))), st.sampled_from(GEOMETRIES))
def test_forward_and_jacobian_are_bit_identical_to_the_numpy_chain(
    q: tuple[float, ...], g: PumaGeometry
) -> None:
    reference = _numpy_frames(q, g)[-1]
    assert forward(q, g).matrix.tobytes() == reference.tobytes()
    assert forward(q, g).matrix.tobytes() == reference.tobytes()  # again: the kept answer
    for frame in ("world", "tool"):
        got = jacobian(q, g, frame=frame)  # type: ignore[arg-type]
        assert got.tobytes() == _numpy_jacobian(q, g, frame).tobytes(), frame
        assert got.flags.c_contiguous and got.flags.writeable


def test_forward_keeps_the_sign_of_zero_angles_apart() -> None:
    # -0.0 == 0.0, but their links' zeros differ in sign: the kept answers must not be mixed up
    for q in ((0.0,) * 6, (-0.0,) * 6, (0.0,) * 6):
        assert forward(q).matrix.tobytes() == _numpy_frames(q, PUMA560_LEE)[-1].tobytes()
    assert not forward(READY).matrix.flags.writeable


# ---------------------------------------------------------------------------- reference vectors
# name: (q_RTB deg, T in metres with the pedestal (rows of [n o a p]), ikine_a solutions by config)
VECTORS = {
    "TV1": (
        (0, 90, -90, 0, 0, 0),
        (
            (1.000000000, 0.000000000, 0.000000000, 0.020300000),
            (0.000000000, 1.000000000, 0.000000000, -0.150050000),
            (0.000000000, 0.000000000, 1.000000000, 1.535430000),
        ),
        {
            "lun": (15.409333, 90.000000, -84.616727, -0.000000, -5.383273, -15.409333),
            "ldn": (15.409333, 92.693122, -90.000000, -0.000000, -2.693122, -15.409333),
            "run": (0.000000, 90.000000, -90.000000, 180.000000, -0.000000, 180.000000),
            "rdn": (0.000000, 87.306878, -84.616727, -0.000000, -2.690150, -0.000000),
            "luf": (15.409333, 90.000000, -84.616727, 180.000000, 5.383273, 164.590667),
            "ldf": (15.409333, 92.693122, -90.000000, 180.000000, 2.693122, 164.590667),
            "ruf": (0.000000, 90.000000, -90.000000, -0.000000, 0.000000, -0.000000),
            "rdf": (0.000000, 87.306878, -84.616727, 180.000000, 2.690150, 180.000000),
        },
    ),
    "TV2": (
        (0, 45, -180, 0, 45, 0),
        (
            (-0.000000000, 0.000000000, 1.000000000, 0.596303149),
            (-0.000000000, 1.000000000, -0.000000000, -0.150050000),
            (-1.000000000, -0.000000000, 0.000000000, 0.657475732),
        ),
        {
            "lun": (151.751379, 135.000000, 5.383273, -34.895033, -55.826119, -158.605780),
            "ldn": (151.751379, -132.242073, -180.000000, -141.367389, -49.296731, -27.528789),
            "run": (0.000000, 45.000000, -180.000000, -180.000000, -45.000000, 180.000000),
            "rdn": (0.000000, -47.757927, 5.383273, -0.000000, -47.625346, -0.000000),
            "luf": (151.751379, 135.000000, 5.383273, 145.104967, 55.826119, 21.394220),
            "ldf": (151.751379, -132.242073, -180.000000, 38.632611, 49.296731, 152.471211),
            "ruf": (0.000000, 45.000000, -180.000000, 0.000000, 45.000000, 0.000000),
            "rdf": (0.000000, -47.757927, 5.383273, 180.000000, 47.625346, -180.000000),
        },
    ),
    "TV3": (
        (30, 60, -120, 20, 40, 60),
        (
            (-0.203760400, -0.882967387, 0.422906954, 0.594640043),
            (0.973318788, -0.229252301, -0.009691209, 0.170052773),
            (0.105509414, 0.409648600, 0.906121288, 1.244099454),
        ),
        {
            "lun": (-178.081485, 120.000000, -54.616727, 2.107829, -40.412067, -80.090446),
            "ldn": (-178.081485, 152.710186, -120.000000, 10.068166, -7.839091, -88.461214),
            "run": (30.000000, 60.000000, -120.000000, -160.000000, -40.000000, -120.000000),
            "rdn": (30.000000, 27.289814, -54.616727, -113.348100, -13.854333, -170.450770),
            "luf": (-178.081485, 120.000000, -54.616727, -177.892171, 40.412067, 99.909554),
            "ldf": (-178.081485, 152.710186, -120.000000, -169.931834, 7.839091, 91.538786),
            "ruf": (30.000000, 60.000000, -120.000000, 20.000000, 40.000000, 60.000000),
            "rdf": (30.000000, 27.289814, -54.616727, 66.651900, 13.854333, 9.549230),
        },
    ),
    "TV4": (
        (-50, 100, -30, 120, -60, -45),
        (
            (0.971040874, 0.160110013, 0.177325701, -0.419496162),
            (-0.130868822, -0.264501922, 0.955464329, 0.266499698),
            (0.199882395, -0.951001323, -0.235888769, 1.263830046),
        ),
        {
            "lun": (-50.000000, 100.000000, -30.000000, 120.000000, -60.000000, -45.000000),
            "ldn": (-50.000000, 157.342925, -144.616727, 131.120064, -95.391772, -92.036966),
            "run": (165.145619, 80.000000, -144.616727, -75.830540, -91.986986, -37.525504),
            "rdn": (165.145619, 22.657075, -30.000000, -83.927118, -102.976679, -94.354981),
            "luf": (-50.000000, 100.000000, -30.000000, -60.000000, 60.000000, 135.000000),
            "ldf": (-50.000000, 157.342925, -144.616727, -48.879936, 95.391772, 87.963034),
            "ruf": (165.145619, 80.000000, -144.616727, 104.169460, 91.986986, 142.474496),
            "rdf": (165.145619, 22.657075, -30.000000, 96.072882, 102.976679, 85.645019),
        },
    ),
    "TV5": (
        (120, 30, -150, -80, 70, 200),
        (
            (0.061529057, -0.124362349, -0.990327310, -0.238927658),
            (-0.620811325, 0.772154976, -0.135535940, 0.713934842),
            (0.781541729, 0.623145809, -0.029695587, 0.654249684),
        ),
        {
            "lun": (-82.993014, 150.000000, -24.616727, -91.842484, -89.655384, 16.044227),
            "ldn": (-82.993014, -147.269840, -150.000000, -91.152795, -91.478116, 78.676926),
            "run": (120.000000, 30.000000, -150.000000, 100.000000, -70.000000, 20.000000),
            "rdn": (120.000000, -32.730160, -24.616727, 76.110509, -72.418886, 86.578920),
            "luf": (-82.993014, 150.000000, -24.616727, 88.157516, 89.655384, -163.955773),
            "ldf": (-82.993014, -147.269840, -150.000000, 88.847205, 91.478116, -101.323074),
            "ruf": (120.000000, 30.000000, -150.000000, -80.000000, 70.000000, -160.000000),
            "rdf": (120.000000, -32.730160, -24.616727, -103.889491, 72.418886, -93.421080),
        },
    ),
}


def _rtb_pose_in_lee_world(rows: Sequence[Sequence[float]]) -> Transform:
    """The toolbox matrix (metres, with pedestal) as our pose: mm, shoulder origin, frames turned."""
    m = np.vstack([np.array(rows, dtype=float), [0, 0, 0, 1]])
    m[:3, 3] *= 1000.0
    m[2, 3] -= PEDESTAL_MM
    return Transform(_rz(180) @ m @ _rz(180))


@pytest.mark.parametrize("name", sorted(VECTORS))
def test_notes_vectors_forward(name: str) -> None:
    q_rtb, rows, _ = VECTORS[name]
    expected = _rtb_pose_in_lee_world(rows)
    got = forward(np.array(q_rtb) + RTB_TO_LEE, PUMA560_CORKE)
    assert np.allclose(got.matrix, expected.matrix, rtol=0.0, atol=1e-6)


@pytest.mark.parametrize("name", sorted(VECTORS))
def test_notes_vectors_inverse(name: str) -> None:
    """Each toolbox configuration is one of ours: same arm and elbow letters; its 'n' is our FLIP."""
    q_rtb, _, solutions = VECTORS[name]
    pose = forward(np.array(q_rtb) + RTB_TO_LEE, PUMA560_CORKE)
    ours = inverse_all(pose, PUMA560_CORKE, None)
    assert 4 <= len(ours) <= 8
    for letters, q_ref in solutions.items():
        want = np.array(q_ref) + RTB_TO_LEE
        lefty, above, flip = letters[0] == "l", letters[1] == "u", letters[2] == "n"
        singular = abs(want[4]) < WRIST_SINGULAR_DEG
        matches = [s for s in ours if (s.lefty, s.above) == (lefty, above) and (singular or s.flip == flip)]
        assert len(matches) == 1, (letters, matches)
        got = np.array(matches[0].q)
        assert configuration(got, PUMA560_CORKE)[:2] == (lefty, above)
        assert singular or configuration(got, PUMA560_CORKE)[2] == flip
        if singular:  # only J4 + J6 is defined; the toolbox and we split it differently
            assert matches[0].singular
            got[[3, 5]] = (0.0, got[3] + got[5])
            want[[3, 5]] = (0.0, want[3] + want[5])
        assert all(abs(wrap_deg(a - b)) < 1e-6 for a, b in zip(got, want, strict=True)), (letters, got, want)


# ---------------------------------------------------------------------------- inverse round trips
@FAST
@given(regular_q, st.sampled_from(GEOMETRIES))
def test_every_solution_reaches_the_pose(q: tuple[float, ...], g: PumaGeometry) -> None:
    assume(_well_conditioned(q, g))
    pose = forward(q, g)
    solutions = inverse_all(pose, g)
    configs = {(s.lefty, s.above, s.flip) for s in solutions}
    assert len(configs) == 8
    for s in solutions:
        d = forward(s.q, g).distance(pose)
        assert d.translation_mm < 1e-6 and d.rotation_deg < 1e-6, (s, d)
        assert configuration(s.q, g) == (s.lefty, s.above, s.flip)
        assert list(s.out_of_range) == within_limits(s.q)


@FAST
@given(regular_q, st.sampled_from(GEOMETRIES))
def test_nearest_to_the_current_angles_is_the_current_angles(q: tuple[float, ...], g: PumaGeometry) -> None:
    assume(_well_conditioned(q, g))
    got = inverse_nearest(forward(q, g), q, g)
    assert np.allclose(got, q, rtol=0.0, atol=1e-6), (got, q)


def test_plus_minus_360_variants_follow_the_current_angles() -> None:
    q = (120.0, -150.0, 30.0, -80.0, 70.0, 200.0)  # TV5 in our convention; J6 = 200 ≡ −160
    pose = forward(q)
    assert inverse_nearest(pose, q)[5] == pytest.approx(200.0)
    assert inverse_nearest(pose, (*q[:5], -150.0))[5] == pytest.approx(-160.0)
    q2 = (10.0, -200.0, 100.0, 10.0, 30.0, 0.0)  # J2 past −180: only the variant is in range
    assert np.allclose(inverse_nearest(forward(q2), q2), q2, atol=1e-9)
    sols = [s for s in inverse_all(forward(q2)) if (s.lefty, s.above, s.flip) == configuration(q2)]
    assert sols[0].out_of_range == (2,) and any(s.q[1] == pytest.approx(-200.0) for s in sols[1:])
    assert all(not s.out_of_range for s in sols[1:])


def test_wrist_singularity_keeps_current_j4() -> None:
    q = (20.0, -60.0, 120.0, 40.0, 0.0, 15.0)
    pose = forward(q)
    for j4 in (40.0, -30.0, 150.0):
        got = inverse_nearest(pose, (20.0, -60.0, 120.0, j4, 0.0, 0.0))
        assert got[3] == pytest.approx(j4) and got[4] == pytest.approx(0.0, abs=1e-12)
        assert got[3] + got[5] == pytest.approx(55.0)
        assert forward(got).almost_equal(pose, 1e-9)
    nearly = forward((20.0, -60.0, 120.0, 40.0, 0.5 * WRIST_SINGULAR_DEG, 15.0))
    got = inverse_nearest(nearly, (20.0, -60.0, 120.0, -30.0, 0.0, 0.0))
    assert got[3] == pytest.approx(-30.0)
    assert forward(got).distance(nearly).rotation_deg <= WRIST_SINGULAR_DEG
    lefty, above, _ = configuration(q)
    same = [s for s in inverse_all(pose, limits=None) if (s.lefty, s.above) == (lefty, above)]
    assert len(same) == 1 and same[0].singular  # flip and noflip coincide there


def test_wrist_singularity_brings_an_out_of_range_j4_into_range() -> None:
    """Current J4 just past a limit: the singular solution takes the nearest in-range J4 and gives J6
    the rest, instead of holding J4 past its limit and answering JOR."""
    pose = forward((0.0, 9.0, -40.0, 0.0, 0.0, 0.0))
    for j4, held in ((-111.0, -110.0), (175.0, 170.0), (-400.0, -110.0)):
        got = nearest_solution(pose, (0.0, 0.0, 0.0, j4, 0.0, 0.0))
        assert got.singular and not got.out_of_range and not within_limits(got.q)
        assert got.q[3] == pytest.approx(held)
        assert wrap_deg(got.q[3] + got.q[5]) == pytest.approx(0.0, abs=1e-9)
        assert forward(got.q).almost_equal(pose, 1e-9)
        legal = [s for s in inverse_all(pose, current=(0.0, 0.0, 0.0, j4, 0.0, 0.0)) if s.singular]
        assert legal and all(s.q[3] == pytest.approx(held) for s in legal)


def test_wrist_singularity_j4_leaves_a_narrow_j6_in_range() -> None:
    """With J6's range under 360° not every J4 leaves J6 an in-range angle: J4 moves (least) so that it
    does, J4 + J6 kept at J5 = 0 and J4 − J6 at J5 = 180°."""
    lower, upper = UNIMATION_LIMITS.lower, UNIMATION_LIMITS.upper
    narrow = JointLimits((*lower[:4], -200.0, -90.0), (*upper[:4], 200.0, 90.0))
    arm = (100.0, 100.0, 100.0, 1.0, 1.0, 1.0)  # keeps the other configurations out of it
    pose = forward((20.0, -60.0, 120.0, 100.0, 0.0, 50.0))  # J4 + J6 = 150: J4 in [60, 170]
    for j4, want in ((0.0, 60.0), (-111.0, 60.0), (100.0, 100.0), (175.0, 170.0)):
        got = nearest_solution(pose, (20.0, -60.0, 120.0, j4, 0.0, 0.0), limits=narrow, weights=arm)
        assert got.singular and not narrow.violations(got.q)
        assert got.q[3] == pytest.approx(want, abs=1e-5) and got.q[3] + got.q[5] == pytest.approx(150.0)
        assert forward(got.q).almost_equal(pose, 1e-9)
    pose = forward((20.0, -60.0, 120.0, 100.0, 180.0, 20.0))  # J4 − J6 = 80: J4 in [−10, 170]
    for j4, want in ((0.0, 0.0), (-111.0, -10.0), (175.0, 170.0)):
        got = nearest_solution(pose, (20.0, -60.0, 120.0, j4, 180.0, 0.0), limits=narrow, weights=arm)
        assert got.singular and not narrow.violations(got.q)
        assert got.q[3] == pytest.approx(want, abs=1e-5) and got.q[3] - got.q[5] == pytest.approx(80.0)
        assert forward(got.q).almost_equal(pose, 1e-9)


def test_wrist_centre_on_the_j1_axis_brings_an_out_of_range_j1_into_range() -> None:
    """With no shoulder offset and no elbow offset the wrist centre can lie on the J1 axis, where J1 is
    free: it is held at the current J1, or the in-range angle nearest it."""
    g = PumaGeometry(a2=431.8, a3=0.0, d2=0.0, d4=433.07, name="no offsets")
    pose = Transform.trans(0.0, 0.0, 500.0)
    for j1, held in ((30.0, 30.0), (170.0, 160.0), (-200.0, -160.0)):
        got = nearest_solution(pose, (j1, -90.0, 90.0, 0.0, 0.0, 0.0), g)
        assert got.q[0] == pytest.approx(held) and not within_limits(got.q)
        assert forward(got.q, g).almost_equal(pose, 1e-9)


_SINGULAR_Q = st.tuples(*(_joint(j) for j in range(4)), st.just(0.0), _joint(5))


@FAST
@given(_SINGULAR_Q, st.floats(-400.0, 400.0), st.sampled_from(GEOMETRIES))
def test_wrist_singular_poses_are_solved_from_any_current_j4(
    q: tuple[float, ...], j4: float, g: PumaGeometry
) -> None:
    """A pose with J5 = 0 always has an in-range solution (its own configuration, with J4 anywhere in
    range and J6 taking the rest); a singular answer holds J4 at the in-range angle nearest the current."""
    assume(_well_conditioned(q, g))
    pose = forward(q, g)
    current = (*q[:3], j4, 0.0, q[5])
    got = nearest_solution(pose, current, g)
    assert not within_limits(got.q)
    assert forward(got.q, g).distance(pose).rotation_deg <= WRIST_SINGULAR_DEG + 1e-9
    if got.singular:
        held = min(max(j4, UNIMATION_LIMITS.lower[3]), UNIMATION_LIMITS.upper[3])
        assert got.q[3] == pytest.approx(held, abs=1e-9)


@st.composite
def _limits_and_singular_q(draw: st.DrawFn) -> tuple[JointLimits, tuple[float, ...]]:
    """Unimation's limits with J4 and J6 ranges of 10° to 400° anywhere, and legal angles with J5 at or
    near 0."""
    lower, upper = list(UNIMATION_LIMITS.lower), list(UNIMATION_LIMITS.upper)
    for j in (3, 5):
        width, centre = draw(st.floats(10.0, 400.0)), draw(st.floats(-200.0, 200.0))
        lower[j], upper[j] = centre - width / 2, centre + width / 2
    q = [draw(st.floats(lower[j], upper[j])) for j in range(6)]
    # Inside the singular band: just outside it, J4 itself is computed to ~1e-9° only, which a J4 drawn
    # on its limit can overstep (by more than LIMIT_TOL_DEG) when J4's range is too narrow to flip.
    q[4] = draw(st.just(0.0) | st.floats(-0.5 * WRIST_SINGULAR_DEG, 0.5 * WRIST_SINGULAR_DEG))
    return JointLimits(tuple(lower), tuple(upper)), tuple(q)


def _pinned(
    lo4: float, hi4: float, lo6: float, hi6: float, q: Sequence[float]
) -> tuple[JointLimits, tuple[float, ...]]:
    lower, upper = list(UNIMATION_LIMITS.lower), list(UNIMATION_LIMITS.upper)
    lower[3], upper[3], lower[5], upper[5] = lo4, hi4, lo6, hi6
    return JointLimits(tuple(lower), tuple(upper)), tuple(q)


@FAST
@given(_limits_and_singular_q(), _ANY, st.sampled_from(GEOMETRIES))
# J4's and J6's ranges leave J4 one angle (here −11 or −17, J4 + J6 = −3 or −13): a margin, or the
# rounding of J4 + J6, lost it.  With J5 off 0 the fitted J4 + J6 drifts with the held J4 (by 1e-9° from
# J4 = −0.5 to −107.5 at J5 = −5e-4).
@example(_pinned(-11.0, -1.0, 8.0, 18.0, (0.0, 0.0, 0.0, -11.0, 0.0, 8.0)), (0.0,) * 6, PUMA560_LEE)
@example(_pinned(-17.0, -7.0, 4.0, 14.0, (0.0, 0.0, 0.0, -17.0, 0.0, 4.0)), (0.0,) * 6, PUMA560_LEE)
@example(_pinned(-89.0, -1.0, 174.0, 184.0, (0.0, 0.0, 0.0, -89.0, 1e-4, 174.0)), (0.0,) * 6, PUMA560_LEE)
@example(_pinned(-107.5, -0.5, 5.0, 15.0, (0.0, 0.0, 0.0, -107.5, -5e-4, 5.0)), (0.0,) * 6, PUMA560_LEE)
def test_wrist_singular_poses_are_solved_under_narrow_j4_and_j6_ranges(
    limits_q: tuple[JointLimits, tuple[float, ...]], current: tuple[float, ...], g: PumaGeometry
) -> None:
    """The angles themselves are a legal solution, so the singular branch must find one: a J4 in range
    that leaves J6 an angle in range, even when J6's range is under 360° and the two leave J4 one angle."""
    limits, q = limits_q
    pose = forward(q, g)
    got = nearest_solution(pose, current, g, limits)
    assert not limits.violations(got.q)
    reached = forward(got.q, g).distance(pose)
    assert reached.translation_mm < 1e-3 and reached.rotation_deg <= WRIST_SINGULAR_DEG + 1e-9


def test_near_singular_tilt_in_the_held_j4_plane_is_exact() -> None:
    q = (20.0, -60.0, 120.0, 40.0, -0.5 * WRIST_SINGULAR_DEG, 15.0)
    got = nearest_solution(forward(q), (20.0, -60.0, 120.0, 40.0, 0.0, 0.0))
    assert got.singular and np.allclose(got.q, q, atol=1e-9)
    lefty, above, _ = configuration(q)
    assert got.config == " ".join(("LEFTY" if lefty else "RIGHTY", "ABOVE" if above else "BELOW", "FLIP"))


def test_poses_a_hair_outside_the_workspace_are_solved_on_its_boundary() -> None:
    forearm = math.hypot(20.32, 433.07)
    for pose in (
        Transform.trans(0.0, 149.09 - 5e-4, 300.0),  # inside the shoulder-offset cylinder
        Transform.trans(431.8 + forearm + 5e-4, 149.09, 0.0),  # beyond full stretch
    ):
        solutions = inverse_all(pose, limits=None)
        assert len(solutions) == 8
        assert all(forward(s.q).distance(pose).translation_mm < 1e-3 for s in solutions)


def test_illegal_wrist_angle_is_reached_by_another_configuration() -> None:
    q = (30.0, -120.0, 60.0, 20.0, 120.0, 60.0)  # J5 = 120 is outside ±100
    assert within_limits(q) == [5]
    pose = forward(q)
    s = nearest_solution(pose, q)
    assert not within_limits(s.q) and (s.lefty, s.above) != configuration(q)[:2]
    assert forward(s.q).almost_equal(pose, 1e-9)


# ---------------------------------------------------------------------------- errors and limits
@pytest.mark.parametrize(
    ("pose", "why"),
    [
        (Transform.trans(2000.0, 0.0, 0.0), "beyond"),
        (Transform.trans(0.0, 0.0, 500.0), "shoulder offset"),
        (Transform.trans(0.0, 149.09, 0.5), "closer"),
    ],
)
def test_unreachable(pose: Transform, why: str) -> None:
    with pytest.raises(Unreachable, match=why) as info:
        inverse_nearest(pose, READY)
    assert info.value.error_code == "TOR"
    with pytest.raises(Unreachable):
        inverse_all(pose)


def test_every_solution_out_of_range() -> None:
    """Notes §3.3's example, q_RTB = (−154.649, −133.281, 161.398, 43.878, −47.162, 4.1): a transform
    whose every solution breaks a limit, TOR on the wire (erratum transform-refusals)."""
    q = np.array([-154.649, -133.281, 161.398, 43.878, -47.162, 4.1]) + RTB_TO_LEE
    pose = forward(q, PUMA560_CORKE)
    with pytest.raises(OutOfRange) as info:
        inverse_nearest(pose, READY, PUMA560_CORKE)
    err = info.value
    assert err.error_code == "TOR" and err.joints and err.mask == joint_mask(err.joints)
    assert len(err.solutions) == 8 and all(s.out_of_range for s in err.solutions)
    loose = JointLimits((-180.0,) * 6, (180.0,) * 6)
    assert forward(inverse_nearest(pose, READY, PUMA560_CORKE, loose), PUMA560_CORKE).almost_equal(pose, 1e-9)


def test_within_limits_and_mask() -> None:
    assert within_limits(READY) == []
    assert within_limits((170.0, -90.0, 90.0, 0.0, -101.0, 0.0)) == [1, 5]
    assert within_limits((0.0, -225.0, 225.0, 170.0, 100.0, -266.0)) == []
    assert joint_mask([1, 5]) == 0b10001
    with pytest.raises(ValueError):
        within_limits((0.0,) * 5)
    with pytest.raises(ValueError, match="finite"):
        forward((0.0, math.nan, 0.0, 0.0, 0.0, 0.0))
    assert within_limits(np.array(READY)) == []  # arrays are accepted wherever angles are
    with pytest.raises(ValueError):
        JointLimits((0.0,) * 6, (0.0,) * 6)


# ---------------------------------------------------------------------------- Jacobian
@settings(max_examples=40, deadline=None)
@given(legal_q, st.sampled_from(GEOMETRIES), st.sampled_from(["world", "tool"]))
def test_jacobian_matches_finite_differences(q: tuple[float, ...], g: PumaGeometry, frame: str) -> None:
    h = 1e-4  # degrees
    jac = jacobian(q, g, frame=frame)  # type: ignore[arg-type]
    rt = forward(q, g).rotation.T if frame == "tool" else np.eye(3)
    for j in range(6):
        dq = np.zeros(6)
        dq[j] = h
        plus, minus = forward(np.array(q) + dq, g), forward(np.array(q) - dq, g)
        linear = (plus.p - minus.p) / (2 * h)  # mm per degree
        w = plus.rotation @ minus.rotation.T
        angular = np.degrees([w[2, 1] - w[1, 2], w[0, 2] - w[2, 0], w[1, 0] - w[0, 1]]) / 2 / (2 * h)
        assert np.allclose(jac[:3, j], rt @ linear, atol=1e-6)
        assert np.allclose(jac[3:, j], rt @ angular, atol=1e-6)


def test_jacobian_at_ready_and_bad_frame() -> None:
    jac = jacobian(READY)
    assert np.allclose(jac[3:, 0], [0, 0, 1])  # J1 turns about the vertical
    # J2 (axis world y through the origin) swings the wrist centre (−20.32, 149.09, 864.87) about y.
    assert np.allclose(jac[:3, 1], np.array([864.87, 0.0, 20.32]) * math.pi / 180.0)
    assert np.allclose(jac[3:, 3], jac[3:, 5])  # J4 and J6 aligned: the wrist singularity
    with pytest.raises(ValueError):
        jacobian(READY, frame="elbow")  # type: ignore[arg-type]


# ------------------------------------------------------------------- nearest without enumeration
def _brute_nearest(
    pose: Transform, current: Sequence[float], g: PumaGeometry, weights: Sequence[float]
) -> float:
    """The least weighted distance over inverse_all's whole enumeration of in-range solutions."""
    legal = [s for s in inverse_all(pose, g, UNIMATION_LIMITS, current=current) if not s.out_of_range]
    assert legal
    return min(sum(w * (a - b) ** 2 for a, b, w in zip(s.q, current, weights, strict=True)) for s in legal)


_WEIGHTS = st.one_of(
    st.just((1.0,) * 6),
    st.tuples(*(st.sampled_from([0.0, 0.5, 1.0, 3.0]) for _ in range(6))),
    st.tuples(*(st.floats(-1.0, 2.0) for _ in range(6))),
)


@settings(max_examples=300, deadline=None)
@given(legal_q, st.one_of(legal_q, _ANY), st.sampled_from(GEOMETRIES), _WEIGHTS)
# At the wrist singularity J4 was held at the current −111, just past its limit: OutOfRange (JOR).
@example((0.0, 9.0, -40.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, -111.0, 0.0, 0.0), PUMA560_LEE, (1.0,) * 6)
def test_nearest_solution_is_the_least_of_the_enumeration(
    q: tuple[float, ...], current: tuple[float, ...], g: PumaGeometry, weights: tuple[float, ...]
) -> None:
    """nearest_solution picks joint by joint instead of enumerating the ±360° variants: the same least
    weighted distance, an in-range solution that reaches the pose, with its configuration."""
    pose = forward(q, g)
    got = nearest_solution(pose, current, g, weights=weights)
    d = sum(w * (a - b) ** 2 for a, b, w in zip(got.q, current, weights, strict=True))
    assert d == pytest.approx(_brute_nearest(pose, current, g, weights), rel=1e-9, abs=1e-9)
    assert not within_limits(got.q) and not got.out_of_range
    reached = forward(got.q, g).distance(pose)  # off by at most the singular tolerance at the wrist
    assert reached.translation_mm < 1e-3 and reached.rotation_deg <= WRIST_SINGULAR_DEG + 1e-9
    if not got.singular:
        assert configuration(got.q, g) == (got.lefty, got.above, got.flip)
    assert nearest_solution(pose.matrix, current, g, weights=weights) == got  # a bare matrix: the same


def test_nearest_solution_ties_go_to_the_first_of_the_enumeration() -> None:
    """Joint 6 at 120 from a current −60 is as near as at −240 (both in range); with joint 6 out of the
    distance every variant ties.  Either way the first of inverse_all's list wins, as min() over it
    would have it: the wrapped angle."""
    q = (10.0, -80.0, 100.0, 20.0, 30.0, 120.0)
    pose = forward(q)
    heavy = (100.0, 100.0, 100.0, 100.0, 100.0, 1.0)  # keeps the other configurations out of it
    for current, weights in (
        ((*q[:5], -60.0), heavy),
        ((*q[:5], -240.0), (1.0, 1.0, 1.0, 1.0, 1.0, 0.0)),
        ((*q[:5], 250.0), (1.0, 1.0, 1.0, 1.0, 1.0, 0.0)),
    ):
        legal = [s for s in inverse_all(pose, current=current) if not s.out_of_range]
        first = min(
            legal, key=lambda s: sum(w * (a - b) ** 2 for a, b, w in zip(s.q, current, weights, strict=True))
        )
        got = nearest_solution(pose, current, weights=weights)
        assert np.allclose(got.q, first.q, atol=1e-9) and got.q[5] == pytest.approx(120.0)
    assert nearest_solution(pose, (*q[:5], -200.0), weights=heavy).q[5] == pytest.approx(-240.0)
