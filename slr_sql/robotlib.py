"""Robot library: continuous knowledge over numbers, vectors and poses (docs/language.md, "Robot library").

Everything here works on *Python values*, not terms: the engine converts arguments with
:func:`slr_sql.terms.to_python` and results back with :func:`slr_sql.terms.from_python`.

Value kinds
-----------
* **number** -- ``int`` or ``float`` (``bool`` is not a number here).
* **vector** -- a ``list`` (or ``tuple``) of numbers.  A *point* is a vector of length 3.
* **pose**   -- ``Struct("pose", ([x, y, z], [qx, qy, qz, qw]))``: a translation and a rotation
  quaternion in (x, y, z, w) order.  A pose also serves as a rigid transform.

Quaternions use the Hamilton product; a vector ``v`` is rotated by ``q`` as ``q·v·q*``.
Rotation quaternions are normalized before use, so non-unit input is accepted (a zero
quaternion is an error).  Results are always returned as new ``list`` / ``Struct`` objects
with ``float`` components.

Anything that does not fit (mismatched kinds, wrong lengths, non-numbers, a zero quaternion)
raises :class:`RobotValueError`, a ``ValueError`` subclass.
"""
from __future__ import annotations

import math
from typing import Any, Sequence

from .terms import Struct, format_term

__all__ = [
    "RobotValueError", "value_kind", "interpolate", "extrapolate", "pos_multiply", "distance",
    "quat_multiply", "quat_conjugate", "quat_normalize", "quat_rotate", "slerp", "make_pose",
    "pos_multiply_fast", "pose_transform", "pos_multiply_subject",
    "apply_transforms",
]

_INF = math.inf

#: Above this |dot| between two unit quaternions, slerp falls back to normalized lerp.
_NLERP_THRESHOLD = 0.9995


class RobotValueError(ValueError):
    """A value that the robot library cannot handle (wrong kind, length, or a zero quaternion).

    >>> issubclass(RobotValueError, ValueError)
    True
    """


# --------------------------------------------------------------------------- validation


def _is_number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _is_vector(x: Any) -> bool:
    return isinstance(x, (list, tuple)) and all(_is_number(c) for c in x)


def _shown(value: Any) -> str:
    """A value as Prolog text in an error message (never Python's repr of a term).

    >>> _shown(Struct("pose", ([1, 0], [0, 0, 0, 1])))
    'pose([1,0],[0,0,0,1])'
    """
    try:
        return format_term(value)
    except Exception:  # noqa: BLE001 - (a value format_term cannot write): as Python has it
        return repr(value)


def _is_pose(x: Any) -> bool:
    return (isinstance(x, Struct) and x.name == "pose" and len(x.args) == 2
            and _is_vector(x.args[0]) and len(x.args[0]) == 3
            and _is_vector(x.args[1]) and len(x.args[1]) == 4)


def value_kind(v: Any) -> str:
    """Classify a value as ``"number"``, ``"vector"`` or ``"pose"``; raise otherwise.

    >>> value_kind(1.5), value_kind([1, 2]), value_kind(make_pose([0, 0, 0], [0, 0, 0, 1]))
    ('number', 'vector', 'pose')
    """
    if _is_number(v):
        return "number"
    if _is_vector(v):
        return "vector"
    if _is_pose(v):
        return "pose"
    if isinstance(v, Struct) and v.name == "pose":
        raise RobotValueError(
            f"malformed pose {_shown(v)}: expected pose([X,Y,Z],[QX,QY,QZ,QW]) with numbers")
    raise RobotValueError(f"expected a number, a vector or a pose, got {_shown(v)}")


def _number(x: Any, what: str) -> float:
    if not _is_number(x):
        raise RobotValueError(f"{what} must be a number, got {_shown(x)}")
    return x


def _point(p: Any, what: str = "point") -> list[float]:
    if not _is_vector(p) or len(p) != 3:
        raise RobotValueError(f"{what} must be a list of 3 numbers [X,Y,Z], got {_shown(p)}")
    return [float(c) for c in p]


def _pose_parts(p: Any, what: str = "pose") -> tuple[list[float], tuple[float, ...]]:
    if not _is_pose(p):
        raise RobotValueError(f"{what} must be pose([X,Y,Z],[QX,QY,QZ,QW]), got {_shown(p)}")
    return [float(c) for c in p.args[0]], quat_normalize(p.args[1])


def make_pose(translation: Sequence[float], rotation: Sequence[float]) -> Struct:
    """Build ``pose([x,y,z],[qx,qy,qz,qw])`` with float lists (no normalization).

    >>> make_pose([1, 2, 3], [0, 0, 0, 1]).args
    ([1.0, 2.0, 3.0], [0.0, 0.0, 0.0, 1.0])
    """
    return Struct("pose", ([float(c) for c in translation], [float(c) for c in rotation]))


# --------------------------------------------------------------------------- quaternions


def _quat(q: Any, what: str = "quaternion") -> tuple[float, float, float, float]:
    if not _is_vector(q) or len(q) != 4:
        raise RobotValueError(f"{what} must be a list of 4 numbers [QX,QY,QZ,QW], got {_shown(q)}")
    return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))


def quat_normalize(q: Sequence[float]) -> tuple[float, float, float, float]:
    """Unit quaternion in the direction of ``q`` (x, y, z, w); a zero quaternion is an error.

    >>> quat_normalize([0, 0, 0, 2])
    (0.0, 0.0, 0.0, 1.0)
    """
    x, y, z, w = _quat(q)
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not n > 0.0 or math.isinf(n):
        raise RobotValueError(f"cannot normalize quaternion {_shown(list(q))}")
    return (x / n, y / n, z / n, w / n)


def quat_conjugate(q: Sequence[float]) -> tuple[float, float, float, float]:
    """Conjugate ``q*`` of a quaternion (x, y, z, w).

    >>> quat_conjugate([1, 2, 3, 4])
    (-1.0, -2.0, -3.0, 4.0)
    """
    x, y, z, w = _quat(q)
    return (-x, -y, -z, w)


def quat_multiply(q1: Sequence[float], q2: Sequence[float]) -> tuple[float, float, float, float]:
    """Hamilton product ``q1·q2`` of quaternions in (x, y, z, w) order (applies q2 first, then q1).

    >>> quat_multiply([0, 0, 0, 1], [1, 0, 0, 0])
    (1.0, 0.0, 0.0, 0.0)
    """
    x1, y1, z1, w1 = _quat(q1)
    x2, y2, z2, w2 = _quat(q2)
    return (
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
    )


def quat_rotate(q: Sequence[float], v: Sequence[float]) -> list[float]:
    """Rotate the 3-vector ``v`` by the quaternion ``q`` (normalized first): ``q·v·q*``.

    >>> s = math.sqrt(0.5)  # 90 degrees about z
    >>> [round(c, 9) for c in quat_rotate([0, 0, s, s], [1, 0, 0])]
    [0.0, 1.0, 0.0]
    """
    qn = quat_normalize(q)
    px, py, pz = _point(v, "vector to rotate")
    x, y, z, _ = quat_multiply(quat_multiply(qn, (px, py, pz, 0.0)), quat_conjugate(qn))
    return [x, y, z]


def slerp(q1: Sequence[float], q2: Sequence[float], s: float) -> tuple[float, float, float, float]:
    """Spherical linear interpolation from ``q1`` (s=0) to ``q2`` (s=1), shortest path.

    Both inputs are normalized; if their dot product is negative ``q2`` is negated so the
    shorter arc is taken.  When they are nearly parallel (|dot| > 0.9995) normalized linear
    interpolation is used instead.  ``s`` outside [0, 1] extrapolates along the same great
    circle (keeps rotating at the same angular rate).  The result is a unit quaternion; at
    s=0 it equals ``q1`` and at s=1 it equals ``q2`` up to sign (both normalized).

    >>> s = math.sqrt(0.5)
    >>> [round(c, 6) for c in slerp([0, 0, 0, 1], [0, 0, s, s], 0.5)]  # 45 degrees about z
    [0.0, 0.0, 0.382683, 0.92388]
    """
    s = _number(s, "slerp parameter")
    a = quat_normalize(q1)
    b = quat_normalize(q2)
    dot = sum(x * y for x, y in zip(a, b))
    if dot < 0.0:
        b = tuple(-c for c in b)
        dot = -dot
    if dot > _NLERP_THRESHOLD:
        out = [x + (y - x) * s for x, y in zip(a, b)]
        try:
            return quat_normalize(out)
        except RobotValueError:  # only reachable with absurd extrapolation
            raise RobotValueError(f"slerp degenerated at s={s!r}") from None
    theta = math.acos(min(1.0, dot))
    sin_theta = math.sin(theta)
    wa = math.sin((1.0 - s) * theta) / sin_theta
    wb = math.sin(s * theta) / sin_theta
    return quat_normalize([wa * x + wb * y for x, y in zip(a, b)])


# --------------------------------------------------------------------------- public API


def interpolate(t: float, v1: Any, t1: float, v2: Any, t2: float) -> Any:
    """Value at time ``t`` given observations ``v1`` at ``t1`` and ``v2`` at ``t2``.

    Numbers and vectors are interpolated linearly (vectors elementwise, equal lengths
    required); poses linearly on translation and by :func:`slerp` on rotation (shortest
    path, result normalized).  With ``s = (t - t1) / (t2 - t1)``, ``t`` outside
    ``[t1, t2]`` *extrapolates*: linearly for numbers, vectors and translations, and by
    continuing the rotation at the same angular rate for quaternions.  If ``t1 == t2`` the
    result is ``v1`` (returned unchanged).  ``v1`` and ``v2`` must be of the same kind, else
    :class:`RobotValueError`.  Numeric results are floats.

    >>> interpolate(1.5, 10, 1, 20, 2), interpolate(0.5, [0, 0], 0, [2, 4], 1)
    (15.0, [1.0, 2.0])
    """
    t = _number(t, "time T")
    t1 = _number(t1, "time T1")
    t2 = _number(t2, "time T2")
    k1 = value_kind(v1)
    k2 = value_kind(v2)
    if k1 != k2:
        raise RobotValueError(f"cannot interpolate between a {k1} ({_shown(v1)}) and a {k2} ({_shown(v2)})")
    if k1 == "vector" and len(v1) != len(v2):
        raise RobotValueError(
            f"cannot interpolate between vectors of lengths {len(v1)} and {len(v2)}")
    if t1 == t2:
        return v1
    s = (t - t1) / (t2 - t1)
    if k1 == "number":
        return float(v1 + (v2 - v1) * s)
    if k1 == "vector":
        return [float(a + (b - a) * s) for a, b in zip(v1, v2)]
    p1, q1 = _pose_parts(v1)
    p2, q2 = _pose_parts(v2)
    return make_pose([a + (b - a) * s for a, b in zip(p1, p2)], slerp(q1, q2, s))


def extrapolate(v1: Any) -> Any:
    """The "hold last value" rule of the paper: the value now is the last observed ``v1``.

    Kept as a function for symmetry with :func:`interpolate`; ``v1`` is returned unchanged.

    >>> extrapolate([1, 2, 3])
    [1, 2, 3]
    """
    return v1


def _compose(ta: list[float], qa: tuple, tp: list[float], qp: tuple) -> tuple[list[float], tuple]:
    """Transform A=(ta, qa) applied to pose P=(tp, qp): (ta + qa·tp·qa*, qa·qp)."""
    r = quat_rotate(qa, tp)
    return [a + b for a, b in zip(ta, r)], quat_normalize(quat_multiply(qa, qp))


def pos_multiply(p: Any, transforms: Sequence[Any]) -> Any:
    """Transform the point or pose ``p`` by ``transforms[0]``, then ``transforms[1]``, ...

    Each transform is a pose ``A = pose(T, Q)`` mapping a point ``x`` to ``Q·x·Q* + T``.  For
    ``pos_multiply(P, [A, B])`` the result is ``B·(A·P)`` -- e.g. ``[RelPos, CamToBase,
    BaseToWorld]`` gives the world position.  A point ``[x,y,z]`` gives a point; a pose gives
    a pose whose rotation is composed (``QB·QA·QP``, normalized).  Quaternions are normalized
    before use.  An empty ``transforms`` returns ``p`` as floats.

    >>> s = math.sqrt(0.5)
    >>> [round(c, 9) for c in pos_multiply([1, 0, 0], [make_pose([0, 0, 5], [0, 0, s, s])])]
    [0.0, 1.0, 5.0]
    """
    fast = pos_multiply_fast(p, transforms)
    if fast is not None:
        return fast
    return _pos_multiply_checked(p, transforms)


def _pos_multiply_checked(p: Any, transforms: Sequence[Any]) -> Any:
    """pos_multiply through the general helpers: every value validated with a clear error."""
    if not isinstance(transforms, (list, tuple)):
        raise RobotValueError(f"pos_multiply expects a list of pose transforms, got {_shown(transforms)}")
    parts = [_pose_parts(a, f"transform #{i + 1}") for i, a in enumerate(transforms)]
    if _is_pose(p):
        t, q = _pose_parts(p)
        for ta, qa in parts:
            t, q = _compose(ta, qa, t, q)
        return make_pose(t, q)
    if _is_vector(p) and len(p) == 3:
        x = _point(p)
        for ta, qa in parts:
            r = quat_rotate(qa, x)
            x = [a + b for a, b in zip(ta, r)]
        return x
    raise RobotValueError(
        f"pos_multiply: first element must be a point [X,Y,Z] or a pose, got {_shown(p)}")


# --------------------------------------------------------------------------- fast paths
# pos_multiply runs once per candidate match of an event rule's ``where`` goal (the paper's
# softDrinkRec rule), so its common case -- plain floats and ints in plain lists, poses as
# Struct("pose", ([x, y, z], [qx, qy, qz, qw])) -- is done inline here, without the
# validating helpers' calls and intermediate tuples. The arithmetic is *the same sequence
# of float operations* as quat_normalize / quat_multiply / quat_rotate (terms with a zero
# factor included), so the results are bit for bit those of the general path; anything else
# (other number types, a zero quaternion, a malformed value) returns None and takes the
# general path, which raises its RobotValueError.


def _floats(v: Any, n: int) -> tuple | None:
    """``v`` as a tuple of ``n`` floats when it is a list/tuple of exactly ``n`` plain ints or
    floats (not bools, not subclasses); else None."""
    tv = type(v)
    if (tv is not list and tv is not tuple) or len(v) != n:
        return None
    for c in v:
        if type(c) is not float:
            break
    else:   # (floats only, the common case: no conversion)
        return tuple(v)
    out = []
    for c in v:
        tc = type(c)
        if tc is float:
            out.append(c)
        elif tc is int:
            out.append(float(c))
        else:
            return None
    return tuple(out)


def _unit(x: float, y: float, z: float, w: float) -> tuple | None:
    """quat_normalize's arithmetic on floats; None for a zero or infinite norm."""
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not n > 0.0 or n == _INF:
        return None
    return (x / n, y / n, z / n, w / n)


def _rotate(q: tuple, px: float, py: float, pz: float) -> tuple:
    """quat_rotate(q, p) for a unit ``q`` already normalized once: quat_rotate normalizes
    again, then forms (q·(p, 0))·q* with quat_multiply's operation order."""
    q = _unit(*q)
    if q is None:  # cannot happen for a unit quaternion; keep the general path's error
        raise RobotValueError("cannot normalize quaternion")
    return _rotate_by(q, px, py, pz)


def _rotate_by(q: tuple, px: float, py: float, pz: float) -> tuple:
    """(q·(p, 0))·q* with quat_multiply's operation order, ``q`` as quat_rotate has it
    (normalized by quat_rotate itself)."""
    x1, y1, z1, w1 = q
    a = w1 * px + x1 * 0.0 + y1 * pz - z1 * py
    b = w1 * py - x1 * pz + y1 * 0.0 + z1 * px
    c = w1 * pz + x1 * py - y1 * px + z1 * 0.0
    d = w1 * 0.0 - x1 * px - y1 * py - z1 * pz
    x2, y2, z2, w2 = -x1, -y1, -z1, w1
    return (d * x2 + a * w2 + b * z2 - c * y2,
            d * y2 - a * z2 + b * w2 + c * x2,
            d * z2 + a * y2 - b * x2 + c * w2)


def _pose_floats(v: Any) -> tuple | None:
    """(translation floats, unit rotation) of a plain pose value, else None."""
    if type(v) is not Struct or v.name != "pose" or len(v.args) != 2:
        return None
    t = _floats(v.args[0], 3)
    q = _floats(v.args[1], 4)
    if t is None or q is None:
        return None
    q = _unit(*q)
    if q is None:
        return None
    return t, q


def pose_transform(translation: Any, rotation: Any) -> tuple | None:
    """The pose ``pose(translation, rotation)`` (plain lists of numbers) as pos_multiply
    applies it: ``(translation floats, unit rotation, the rotation as quat_rotate turns by
    it)`` -- the rotation normalized once, as the transform's own, and once more, as
    quat_rotate normalizes what it is given. None when the general path must decide.
    Worked out once, a transform applies to any number of points (:func:`apply_transforms`).

    >>> pose_transform([0, 0, 5], [0, 0, 0, 2])
    ((0.0, 0.0, 5.0), (0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0, 1.0))
    >>> pose_transform([0, 0], [0, 0, 0, 1]) is None
    True
    """
    t = _floats(translation, 3)
    q = _floats(rotation, 4)
    if t is None or q is None:
        return None
    q = _unit(*q)
    if q is None:
        return None
    turn = _unit(*q)
    if turn is None:  # (never for a unit quaternion: then the general path raises)
        return None
    return t, q, turn


def _transform_of(v: Any) -> tuple | None:
    """:func:`pose_transform` of a plain pose value, else None."""
    if type(v) is not Struct or v.name != "pose" or len(v.args) != 2:
        return None
    return pose_transform(v.args[0], v.args[1])


def pos_multiply_subject(p: Any) -> tuple | None:
    """What pos_multiply moves, ready for :func:`apply_transforms`: ``("point", (x, y, z))``
    for a plain point, ``("pose", (translation, unit rotation))`` for a plain pose; None
    when the general path must decide.

    >>> pos_multiply_subject([1, 0, 0])
    ('point', (1.0, 0.0, 0.0))
    >>> pos_multiply_subject(Struct("pose", ([1, 2, 3], [0, 0, 0, 2])))
    ('pose', ((1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0)))
    """
    x = _floats(p, 3)
    if x is not None:
        return ("point", x)
    pose = _pose_floats(p)
    return None if pose is None else ("pose", pose)


def apply_transforms(subject: tuple, transforms: Sequence[tuple]) -> Any:
    """pos_multiply of a subject (:func:`pos_multiply_subject`) by transforms
    (:func:`pose_transform`): a point as a list of floats, a pose as ``pose`` of two lists;
    None when a composed rotation cannot be normalized (the general path raises then).

    >>> apply_transforms(("point", (1.0, 0.0, 0.0)),
    ...                  [pose_transform([0, 0, 5], [0, 0, 0, 1])])
    [1.0, 0.0, 5.0]
    """
    kind, value = subject
    if kind == "point":
        px, py, pz = value
        for (tx, ty, tz), _, (x1, y1, z1, w1) in transforms:
            # _rotate_by inline (the hot loop of a where goal over many matches)
            a = w1 * px + x1 * 0.0 + y1 * pz - z1 * py
            b = w1 * py - x1 * pz + y1 * 0.0 + z1 * px
            c = w1 * pz + x1 * py - y1 * px + z1 * 0.0
            d = w1 * 0.0 - x1 * px - y1 * py - z1 * pz
            x2, y2, z2 = -x1, -y1, -z1
            px, py, pz = (tx + (d * x2 + a * w1 + b * z2 - c * y2),
                          ty + (d * y2 - a * z2 + b * w1 + c * x2),
                          tz + (d * z2 + a * y2 - b * x2 + c * w1))
        return [px, py, pz]
    t, q = value
    for (tx, ty, tz), qa, turn in transforms:
        rx, ry, rz = _rotate_by(turn, *t)
        x1, y1, z1, w1 = qa
        x2, y2, z2, w2 = q
        q = _unit(w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                  w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                  w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
                  w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2)
        if q is None:
            return None
        t = (tx + rx, ty + ry, tz + rz)
    return Struct("pose", (list(t), list(q)))


def pos_multiply_fast(p: Any, transforms: Any) -> Any:
    """pos_multiply's common case (plain numbers in lists or tuples, see above), or None
    when the general path must decide (and raise its error).

    >>> pos_multiply_fast((1, 0, 0), [Struct("pose", ((0, 0, 5), (0, 0, 0, 1)))])
    [1.0, 0.0, 5.0]
    >>> pos_multiply_fast([1, 0, 0], ["not a pose"]) is None
    True
    """
    tt = type(transforms)
    if tt is not list and tt is not tuple:
        return None
    parts = []
    for a in transforms:
        part = _transform_of(a)
        if part is None:
            return None
        parts.append(part)
    subject = pos_multiply_subject(p)
    if subject is None:
        return None
    return apply_transforms(subject, parts)


def distance(p1: Any, p2: Any) -> float:
    """Euclidean distance between two points/vectors (equal lengths), two poses (their
    translations) or two numbers (absolute difference).  Mixed kinds raise RobotValueError.

    >>> distance([0, 0, 0], [3, 4, 0]), distance(2, 5)
    (5.0, 3.0)
    """
    k1 = value_kind(p1)
    k2 = value_kind(p2)
    if k1 != k2:
        raise RobotValueError(f"cannot measure distance between a {k1} ({_shown(p1)}) and a {k2} ({_shown(p2)})")
    if k1 == "number":
        return float(abs(p1 - p2))
    if k1 == "pose":
        p1, p2 = p1.args[0], p2.args[0]
    elif len(p1) != len(p2):
        raise RobotValueError(
            f"cannot measure distance between vectors of lengths {len(p1)} and {len(p2)}")
    return math.sqrt(sum((float(a) - float(b)) ** 2 for a, b in zip(p1, p2)))
