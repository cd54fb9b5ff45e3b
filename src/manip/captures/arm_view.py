"""Pictures of the arm for Foxglove: the hand's pose and the joint angles, from the replies that carry them.

Two channels of a capture (written by the recorder with the decoded view):

``/arm/hand`` (``json``, schema ``foxglove.FrameTransform``)
    The hand's pose, world to hand, in Foxglove's well-known schema (metres and a unit quaternion), so
    the 3D panel shows the hand moving.  One message after every ``here`` reply (its transform) and
    every ``joint-angles`` reply (the forward kinematics of its angles: the reference arm's geometry,
    :data:`manip.arm.PUMA600`).  A ``solve-backwards`` reply carries a transform too, but of angles the
    client asked about, not of the hand: it is left out.  A transform whose N, O, A columns are not a
    rotation is left out as well (the decoded view still shows it).
``/arm/joints`` (``json``, schema ``manip.JointAngles``)
    The six joint angles of every ``joint-angles`` reply as flat numbers ``j1`` .. ``j6`` (degrees, base
    first), which the plot panel draws as curves (``/arm/joints.j2``).

Both carry the log time of the reply they come from, also as ``timestamp``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from functools import cache
from typing import Any, Final

from manip.arm import PUMA600, Transform
from manip.arm.kinematics import ArmModel, Rows34, forward_rows
from manip.arm.transform import FLOAT_ROTATION_TOL

from .view import Annotation

HAND_TOPIC: Final = "/arm/hand"
JOINTS_TOPIC: Final = "/arm/joints"
FRAME_TRANSFORM_SCHEMA: Final = "foxglove.FrameTransform"
JOINTS_SCHEMA: Final = "manip.JointAngles"
WORLD_FRAME: Final = "world"
HAND_FRAME: Final = "hand"
POSE_OPS: Final = frozenset({"here", "joint-angles"})
"""The replies that say where the hand is."""

_JSON: Final = json.JSONEncoder(separators=(",", ":"))


def _time() -> dict[str, Any]:
    return {
        "type": "object",
        "title": "time",
        "properties": {
            "sec": {"type": "integer", "minimum": 0},
            "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
        },
    }


def _numbers(title: str, names: str, description: str) -> dict[str, Any]:
    return {
        "title": title,
        "description": description,
        "type": "object",
        "properties": {n: {"type": "number"} for n in names},
    }


@cache
def frame_transform_schema() -> dict[str, Any]:
    """Foxglove's ``foxglove.FrameTransform`` as JSON Schema: the fields of its documented message."""
    return {
        "title": FRAME_TRANSFORM_SCHEMA,
        "description": "A transform between two reference frames in 3D space",
        "type": "object",
        "properties": {
            "timestamp": {**_time(), "description": "Timestamp of transform"},
            "parent_frame_id": {"type": "string", "description": "Name of the parent frame"},
            "child_frame_id": {"type": "string", "description": "Name of the child frame"},
            "translation": _numbers("foxglove.Vector3", "xyz", "Translation component of the transform"),
            "rotation": _numbers("foxglove.Quaternion", "xyzw", "Rotation component of the transform"),
        },
    }


@cache
def joints_schema() -> dict[str, Any]:
    """JSON Schema of ``/arm/joints``: flat, so each joint plots as a curve."""
    joints = {f"j{i}": {"type": "number", "description": f"joint {i}, degrees"} for i in range(1, 7)}
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": JOINTS_SCHEMA,
        "description": "Joint angles of a joint-angles reply, degrees, base first",
        "type": "object",
        "properties": {
            "timestamp": _time(),
            "link": {"type": "integer"},
            "conn": {"type": "integer"},
            "request_number": {"type": "integer"},
            **joints,
        },
        "required": ["timestamp", "j1", "j2", "j3", "j4", "j5", "j6"],
        "additionalProperties": False,
    }


def quaternion(rotation: Any) -> tuple[float, float, float, float]:
    """The unit quaternion (x, y, z, w) of a 3x3 rotation matrix, with w >= 0 (Shepperd's method:
    the largest of the four candidates is taken first, so no division is by a small number)."""
    r = [[float(rotation[i][j]) for j in range(3)] for i in range(3)]
    trace = r[0][0] + r[1][1] + r[2][2]
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = ((r[2][1] - r[1][2]) / s, (r[0][2] - r[2][0]) / s, (r[1][0] - r[0][1]) / s, 0.25 * s)
    elif r[0][0] >= r[1][1] and r[0][0] >= r[2][2]:
        s = 2.0 * math.sqrt(1.0 + r[0][0] - r[1][1] - r[2][2])
        q = (0.25 * s, (r[0][1] + r[1][0]) / s, (r[0][2] + r[2][0]) / s, (r[2][1] - r[1][2]) / s)
    elif r[1][1] >= r[2][2]:
        s = 2.0 * math.sqrt(1.0 + r[1][1] - r[0][0] - r[2][2])
        q = ((r[0][1] + r[1][0]) / s, 0.25 * s, (r[1][2] + r[2][1]) / s, (r[0][2] - r[2][0]) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + r[2][2] - r[0][0] - r[1][1])
        q = ((r[0][2] + r[2][0]) / s, (r[1][2] + r[2][1]) / s, 0.25 * s, (r[1][0] - r[0][1]) / s)
    norm = math.sqrt(sum(c * c for c in q))
    x, y, z, w = (c / norm for c in q)
    return (-x, -y, -z, -w) if w < 0.0 else (x, y, z, w)


def _stamp(t_ns: int) -> dict[str, int]:
    sec, nsec = divmod(t_ns, 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def _frame_transform(rotation: Any, p: Any, t_ns: int) -> dict[str, Any]:
    x, y, z = (float(v) / 1000.0 for v in p)
    qx, qy, qz, qw = quaternion(rotation)
    return {
        "timestamp": _stamp(t_ns),
        "parent_frame_id": WORLD_FRAME,
        "child_frame_id": HAND_FRAME,
        "translation": {"x": x, "y": y, "z": z},
        "rotation": {"x": qx, "y": qy, "z": qz, "w": qw},
    }


# Both messages written straight as JSON: the same bytes as _JSON.encode of their dicts (a test compares
# them), a few microseconds less per pose.  json writes a float as its repr and an int as str(int);
# anything that would not be a finite float or a plain int goes through the encoder instead.
_BIG: Final = 1e300
_PARENT_CHILD: Final = (
    f'"parent_frame_id":{json.dumps(WORLD_FRAME)},"child_frame_id":{json.dumps(HAND_FRAME)}'
)


def _hand_json(rotation: Any, p: Any, t_ns: int) -> bytes:
    """``_JSON.encode(_frame_transform(rotation, p, t_ns))``, as bytes."""
    x, y, z = (float(v) / 1000.0 for v in p)
    qx, qy, qz, qw = quaternion(rotation)
    if type(t_ns) is not int or not -_BIG < x + y + z + qx + qy + qz + qw < _BIG:  # NaN fails too
        return _JSON.encode(_frame_transform(rotation, p, t_ns)).encode()
    sec, nsec = divmod(t_ns, 1_000_000_000)
    return (
        f'{{"timestamp":{{"sec":{sec},"nsec":{nsec}}},{_PARENT_CHILD},'
        f'"translation":{{"x":{x!r},"y":{y!r},"z":{z!r}}},'
        f'"rotation":{{"x":{qx!r},"y":{qy!r},"z":{qz!r},"w":{qw!r}}}}}'
    ).encode()


def _joints_json(angles: list[float], link: int, conn: int, request_number: int | None, t_ns: int) -> bytes:
    """The ``/arm/joints`` message (finite angles) as JSON bytes."""
    if (
        type(t_ns) is not int
        or type(link) is not int
        or type(conn) is not int
        or (request_number is not None and type(request_number) is not int)
    ):
        message: dict[str, Any] = {"timestamp": _stamp(t_ns), "link": link, "conn": conn}
        if request_number is not None:
            message["request_number"] = request_number
        message.update({f"j{i}": a for i, a in enumerate(angles, 1)})
        return _JSON.encode(message).encode()
    sec, nsec = divmod(t_ns, 1_000_000_000)
    number = "" if request_number is None else f',"request_number":{request_number}'
    j1, j2, j3, j4, j5, j6 = angles
    return (
        f'{{"timestamp":{{"sec":{sec},"nsec":{nsec}}},"link":{link},"conn":{conn}{number},'
        f'"j1":{j1!r},"j2":{j2!r},"j3":{j3!r},"j4":{j4!r},"j5":{j5!r},"j6":{j6!r}}}'
    ).encode()


# The hand of a here reply, without numpy (a capture may hold thousands): the same acceptance test as
# Transform.from_floats (max |RᵀR − I| and |det R − 1| within FLOAT_ROTATION_TOL) and the same nearest
# rotation (the orthogonal polar factor, here by Newton's iteration instead of an SVD; a property test
# checks both against Transform.from_floats).  A deviation too near the tolerance to call in another
# summation order, or an iteration that does not settle, goes to Transform.from_floats, which decides.

_NEAR_TOL: Final = 1e-12
_POLAR_STEPS: Final = 8


def _rotation_error(r: Sequence[float]) -> float:
    """Largest deviation of the row-major 3x3 ``r`` from a proper rotation."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = r
    ortho = max(
        abs(r00 * r00 + r10 * r10 + r20 * r20 - 1.0),
        abs(r01 * r01 + r11 * r11 + r21 * r21 - 1.0),
        abs(r02 * r02 + r12 * r12 + r22 * r22 - 1.0),
        abs(r00 * r01 + r10 * r11 + r20 * r21),
        abs(r00 * r02 + r10 * r12 + r20 * r22),
        abs(r01 * r02 + r11 * r12 + r21 * r22),
    )
    det = r00 * (r11 * r22 - r12 * r21) - r01 * (r10 * r22 - r12 * r20) + r02 * (r10 * r21 - r11 * r20)
    return max(ortho, abs(det - 1.0))


def _polar(r: Sequence[float]) -> tuple[float, ...] | None:
    """The rotation nearest the row-major, nearly orthonormal 3x3 ``r``: X <- (X + X^-T) / 2 until it
    stops moving (quadratic convergence: three steps from a deviation of 1e-4), or None."""
    x = tuple(r)
    for _ in range(_POLAR_STEPS):
        x00, x01, x02, x10, x11, x12, x20, x21, x22 = x
        c00, c01, c02 = x11 * x22 - x12 * x21, x12 * x20 - x10 * x22, x10 * x21 - x11 * x20
        c10, c11, c12 = x02 * x21 - x01 * x22, x00 * x22 - x02 * x20, x01 * x20 - x00 * x21
        c20, c21, c22 = x01 * x12 - x02 * x11, x02 * x10 - x00 * x12, x00 * x11 - x01 * x10
        h = 0.5 / (x00 * c00 + x01 * c01 + x02 * c02)  # X^-T is the cofactor matrix over det X
        y = (
            0.5 * x00 + h * c00, 0.5 * x01 + h * c01, 0.5 * x02 + h * c02,
            0.5 * x10 + h * c10, 0.5 * x11 + h * c11, 0.5 * x12 + h * c12,
            0.5 * x20 + h * c20, 0.5 * x21 + h * c21, 0.5 * x22 + h * c22,
        )  # fmt: skip
        if max(abs(a - b) for a, b in zip(x, y, strict=True)) <= 1e-15:
            return y
        x = y
    return None


def _here_hand(values: Sequence[Any]) -> tuple[Any, Any] | None:
    """(rotation rows, position) of a here reply's 12 floats, or None when they are not a pose."""
    try:
        v = [float(x) for x in values]
    except (TypeError, ValueError):
        return None
    if not all(math.isfinite(x) for x in v):
        return None
    nx, ny, nz, ox, oy, oz, ax, ay, az, px, py, pz = v
    r = (nx, ox, ax, ny, oy, ay, nz, oz, az)
    err = _rotation_error(r)
    if abs(err - FLOAT_ROTATION_TOL) > _NEAR_TOL:
        if err > FLOAT_ROTATION_TOL:
            return None
        polar = _polar(r)
        if polar is not None:
            return (polar[0:3], polar[3:6], polar[6:9]), (px, py, pz)
    try:
        pose = Transform.from_floats(values, orthonormalise=True)
    except ValueError:
        return None
    return pose.rotation, pose.p


def arm_messages(ann: Annotation, link: int, t_ns: int, model: ArmModel = PUMA600) -> list[tuple[str, bytes]]:
    """The ``/arm/*`` messages of one annotated packet (none unless it is a pose-bearing reply)."""
    fields = ann.fields
    if ann.kind != "reply" or ann.op not in POSE_OPS or not fields:
        return []
    out: list[tuple[str, bytes]] = []
    hand: tuple[Any, Any] | None = None
    if ann.op == "here":
        values = fields.get("transform")
        if isinstance(values, Sequence) and len(values) == 12:
            hand = _here_hand(values)
    else:
        joints = fields.get("joints")
        if isinstance(joints, Sequence) and len(joints) == 6:
            angles = [float(a) for a in joints]
            if all(math.isfinite(a) for a in angles):
                rows: Rows34 = forward_rows(angles, model.geometry)
                hand = rows, (rows[0][3], rows[1][3], rows[2][3])
                out.append((JOINTS_TOPIC, _joints_json(angles, link, ann.conn, ann.request_number, t_ns)))
    if hand is not None:
        out.insert(0, (HAND_TOPIC, _hand_json(hand[0], hand[1], t_ns)))
    return out
