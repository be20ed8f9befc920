"""tf2's ``lookupTransform`` over stored transforms: the frame tree, chains, interpolation.

The stored transforms are events ``tf(Parent, Child, pose([X,Y,Z],[QX,QY,QZ,QW]))^T`` (the
pose of Child in Parent at T, which maps Child's coordinates into Parent's, as
``geometry_msgs/TransformStamped``) and, for transforms that never change,
``tf_static(Parent, Child, pose(..))^T`` (``slr ros import`` and the bridge store
``/tf_static`` so). :func:`lookup` gives the pose of frame ``source`` in frame ``target`` at
time ``t`` (docs/language.md, "tf_lookup"):

* **the frame tree** is every (Parent, Child) pair stored in ``tf`` or ``tf_static``, taken
  as undirected edges; the chain is the shortest path from ``source`` to ``target``
  (breadth first, neighbours in the order the edges were first stored). An edge is walked
  as stored from Child to Parent, inverted from Parent to Child;
* **a tf edge** at ``t`` is its observation at ``t`` if there is one, else the interpolation
  between the last observation before ``t`` and the first after it (translation linearly,
  rotation by slerp, the robot library's ``interpolate``). Outside its observations the
  lookup fails; with ``extrapolate`` the nearest observation is held instead. Several
  observations at one time: the last stored counts. An observation over an interval
  ``^[T1, T2]`` holds at every time inside it and is its pose at each end for the
  interpolation outside it. Of the observations holding at ``t`` the one that started last
  counts (a point inside an interval counts at its time only); when none holds, the
  interpolation starts from the one that ended last before ``t``;
* **a tf_static edge** (a pair never seen in ``tf``) holds its last stored value at every
  time.

:class:`FrameTree` keeps the edges between calls and reads only the events stored since
(by arrival sequence), so a lookup costs one small statement per type plus one indexed
statement per edge of the chain; chains are cached until a new edge appears. The store is
any object with ``distinct_pairs``, ``bracket`` (see :mod:`slr_sql.store`).

>>> from slr_sql.store import EventStore
>>> from slr_sql.terms import Struct
>>> s = EventStore(None)
>>> s.add_events([("tf", ("map", "base", Struct("pose", ([t, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]))), t, t)
...               for t in (0.0, 2.0)] + [("tf_static", ("base", "cam", Struct("pose", (
...               [0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 1.0]))), 0.0, 0.0)])
[]
>>> lookup(s, FrameTree(), "map", "cam", 1.5)
((1.5, 0.0, 1.0), (0.0, 0.0, 0.0, 1.0))
>>> lookup(s, FrameTree(), "map", "cam", 3.0) is None  # after the last map->base observation
True
"""
from __future__ import annotations

import math
from collections import deque
from typing import Any, Callable

from .robotlib import slerp
from .lockorder import ordered_lock
from .terms import Atom, String, Struct, list_items

__all__ = ["TF", "TF_STATIC", "FrameTree", "frame_key", "Pose", "lookup", "pose_value", "compose",
           "invert", "IDENTITY", "TfHooks", "PoseOverflow"]

TF = ("tf", 3)
_EDGES_BETWEEN_CLOCK_CHECKS = 32   # edges read between two looks at the query's deadline
TF_STATIC = ("tf_static", 3)

Pose = tuple  # ((x, y, z), (qx, qy, qz, qw)) with a unit quaternion
IDENTITY: Pose = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))


class TfHooks:
    """What a synchronized evaluation must wait for (slr_sql.sync): ``prev(key, t)`` — the
    history of ``key`` complete up to ``t``; ``next(key, lo, hi, args)`` — as ``next`` over
    [lo, hi] with the pattern ``args``; ``arrival(key, t, args)`` — an event matching
    ``args`` starting at or after ``t`` has yet to arrive. Each may raise to stop the
    evaluation; the defaults do nothing (an unsynchronized query)."""

    def __init__(self, prev: Callable | None = None, next: Callable | None = None,
                 arrival: Callable | None = None):
        self.prev = prev
        self.next = next
        self.arrival = arrival


def frame_key(frame: Any) -> Any:
    """A frame name as a key of the tree: frame ids are names, and the terms ``1`` and
    ``1.0`` (equal in Python and in SQL) name two frames, as ``-0.0`` and ``0.0`` do, and
    the atom ``map`` and the string ``"map"`` (equal as Python strings).

    >>> frame_key(1) == frame_key(1.0), frame_key(Atom("map")) == frame_key(String("map"))
    (False, False)
    """
    kind = type(frame)
    if kind is float:
        return ("float", repr(frame))
    if kind is String:
        return ("string", str(frame))
    return frame


class FrameTree:
    """The edges of the stored frame tree, kept up to date incrementally (keyed by
    :func:`frame_key`).

    >>> FrameTree().path("a", "a")
    []
    """

    def __init__(self) -> None:
        self.seen = {TF: 0, TF_STATIC: 0}      # arrival sequence read up to, per type
        self.kind: dict[tuple, tuple] = {}      # (parent key, child key) -> TF or TF_STATIC
        # (parent key, child key) -> the longest duration of its tf observations (0: points)
        self.longest: dict[tuple, float] = {}
        self.neighbours: dict[Any, list] = {}   # frame key -> [(frame key, parent, child)]
        self.paths: dict[tuple, list | None] = {}
        self.lock = ordered_lock("frames")   # the threads of one knowledge base share the tree
        self._resets = 0   # how often the tree was read again from the start

    def chain(self, store: Any, target: Any, source: Any) -> list | None:
        """:meth:`refresh`, then :meth:`path`."""
        self.refresh(store)
        with self.lock:
            return self.path(target, source)

    def refresh(self, store: Any) -> None:
        """Read the (parent, child) pairs stored since the last refresh.

        The store is read without the tree's lock: a thread inside a transaction (holding
        the store's lock) may look a transform up, so the tree's lock comes after the
        store's and is never held while waiting for it. Two threads may read the same new
        pairs; adding a pair again changes nothing."""
        while True:
            with self.lock:
                seen, resets = dict(self.seen), self._resets
            read = {key: store.distinct_pairs(key[0], key[1], seen[key])
                    for key in (TF, TF_STATIC)}
            with self.lock:
                if self._resets != resets:    # another thread started again meanwhile
                    continue
                if any(top < seen[key] for key, (_pairs, top) in read.items()):
                    # the newest events were deleted: read all again
                    self.seen = {TF: 0, TF_STATIC: 0}
                    self.kind.clear()
                    self.longest.clear()
                    self.neighbours.clear()
                    self.paths.clear()
                    self._resets += 1
                    continue
                for key, (pairs, top) in read.items():
                    if top <= self.seen[key]:   # another thread added these already
                        continue
                    # (read from where the tree was or earlier: the pairs it has come first)
                    self.seen[key] = top
                    for parent, child, longest in pairs:
                        self._add(parent, child, key, longest)
                return

    def _add(self, parent: Any, child: Any, key: tuple, longest: float = 0.0) -> None:
        parent_key, child_key = frame_key(parent), frame_key(child)
        pair = (parent_key, child_key)
        if key == TF and longest > self.longest.get(pair, 0.0):
            self.longest[pair] = longest
        old = self.kind.get(pair)
        if old == TF or old == key:
            return
        self.kind[pair] = key   # a pair seen in tf is a tf edge, even if also static
        self.paths.clear()
        if old is None:
            self.neighbours.setdefault(child_key, []).append((parent_key, parent, child))
            self.neighbours.setdefault(parent_key, []).append((child_key, parent, child))

    def path(self, target: Any, source: Any) -> list | None:
        """The edges from ``source`` to ``target``: ``[(parent, child, inverse)]`` in the
        order they apply (``inverse``: walked from parent to child); None when the frames
        are not connected."""
        target, source = frame_key(target), frame_key(source)
        if target == source:
            return []
        key = (target, source)
        if key in self.paths:
            return self.paths[key]
        came: dict[Any, tuple] = {source: ()}
        queue = deque([source])
        found = None
        while queue and found is None:
            frame = queue.popleft()
            for other, parent, child in self.neighbours.get(frame, ()):
                if other in came:
                    continue
                came[other] = (frame, parent, child)
                if other == target:
                    found = other
                    break
                queue.append(other)
        if found is None:
            result = None
        else:
            result = []
            frame = target
            while frame != source:
                before, parent, child = came[frame]
                result.append((parent, child, frame_key(parent) == before))
                frame = before
            result.reverse()
        self.paths[key] = result
        return result


def pose_value(term: Any) -> Pose | None:
    """A stored ``pose([X,Y,Z],[QX,QY,QZ,QW])`` as floats with a unit quaternion; None if
    it is not one (or its quaternion is zero).

    >>> pose_value(Struct("pose", ([1, 2, 3], [0, 0, 0, 2])))
    ((1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0))
    """
    if type(term) is not Struct or term.name != "pose" or len(term.args) != 2:
        return None
    parts = []
    for arg, n in zip(term.args, (3, 4)):
        items = arg if type(arg) is list else list_items(arg)[0]
        if len(items) != n:
            return None
        values = []
        for x in items:
            if type(x) is float:
                values.append(x)
            elif type(x) is int:
                try:
                    values.append(float(x))
                except OverflowError:
                    return None   # beyond any float: no transform, as an infinite one
            else:
                return None
        parts.append(values)
    if not all(math.isfinite(v) for v in parts[0] + parts[1]):
        return None   # tf2 refuses such a transform too
    # the norm of the quaternion scaled to its largest component: squaring 1e200 (or 1e-200)
    # overflows (underflows) where the rotation is a valid one
    scale = max(abs(v) for v in parts[1])
    if not scale > 0.0:
        return None
    qx, qy, qz, qw = (v / scale for v in parts[1])
    norm = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    return (tuple(parts[0]), (qx / norm, qy / norm, qz / norm, qw / norm))


def _rotate(q: tuple, v: tuple) -> tuple:
    """v rotated by the unit quaternion q (q·v·q*, expanded)."""
    qx, qy, qz, qw = q
    vx, vy, vz = v
    big = max(abs(vx), abs(vy), abs(vz))
    if big > 1e300:   # 2 q_vec x v would overflow where v rotated does not: rotate v / big
        x, y, z = _rotate(q, (vx / big, vy / big, vz / big))
        return (x * big, y * big, z * big)
    # t = 2 q_vec x v; v' = v + qw t + q_vec x t
    tx = 2.0 * (qy * vz - qz * vy)
    ty = 2.0 * (qz * vx - qx * vz)
    tz = 2.0 * (qx * vy - qy * vx)
    return (vx + qw * tx + (qy * tz - qz * ty),
            vy + qw * ty + (qz * tx - qx * tz),
            vz + qw * tz + (qx * ty - qy * tx))


def compose(a: Pose, b: Pose) -> Pose:
    """The transform ``a·b``: first ``b``, then ``a`` (a point p goes to a(b(p))).

    >>> compose(((1.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)), ((0.0, 2.0, 0.0), (0.0, 0.0, 0.0, 1.0)))
    ((1.0, 2.0, 0.0), (0.0, 0.0, 0.0, 1.0))
    """
    (ax, ay, az), qa = a
    tb, (x2, y2, z2, w2) = b
    rx, ry, rz = _rotate(qa, tb)
    x1, y1, z1, w1 = qa
    q = (w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
         w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
         w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
         w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2)
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return ((ax + rx, ay + ry, az + rz), (q[0] / n, q[1] / n, q[2] / n, q[3] / n))


def invert(a: Pose) -> Pose:
    """The inverse transform of ``a``.

    >>> invert(((1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0)))
    ((-1.0, -2.0, -3.0), (-0.0, -0.0, -0.0, 1.0))
    """
    t, (qx, qy, qz, qw) = a
    inv = (-qx, -qy, -qz, qw)
    rx, ry, rz = _rotate(inv, t)
    return ((-rx, -ry, -rz), inv)


def _lerp(a: float, b: float, s: float) -> float:
    v = a + (b - a) * s
    if math.isfinite(v):
        return v
    return a * (1.0 - s) + b * s   # b - a overflowed (huge values of opposite signs)


def _interpolate(t: float, t1: float, p1: Pose, t2: float, p2: Pose) -> Pose:
    s = (t - t1) / (t2 - t1)
    (a, b) = p1[0], p2[0]
    q = slerp(p1[1], p2[1], s)
    return ((_lerp(a[0], b[0], s), _lerp(a[1], b[1], s), _lerp(a[2], b[2], s)), tuple(q))


class _Unusable(Exception):
    """A stored edge value that is not a pose: the lookup fails on it."""


class PoseOverflow(ArithmeticError):
    """The pose of a chain is beyond floats (its edges' poses are finite, their composition
    is not): ``tf_lookup`` raises ``evaluation_error(float_overflow)``, as ``is`` does."""


def _edge_pose(row: Any) -> Pose:
    value = pose_value(row[0][2])
    if value is None:
        raise _Unusable()
    return value


def _edge_at(store: Any, key: tuple, parent: Any, child: Any, t: float, extrapolate: bool,
             hooks: TfHooks | None, longest: float = math.inf) -> Pose | None:
    name, arity = key
    bound = {0: parent, 1: child}
    if key == TF_STATIC:
        if hooks is not None and hooks.prev is not None:
            hooks.prev(key, t)
        found = store.bracket(name, arity, bound, math.inf)
        if found is None or found[0] is None:
            return None
        return _edge_pose(found[0])
    if hooks is not None and hooks.prev is not None:
        hooks.prev(key, t)
    found = store.bracket(name, arity, bound, t, longest)
    if found is None:
        return None
    before, after = found
    if before is not None and before[2] >= t:   # an observation at t, an interval around t
        return _edge_pose(before)
    args = (parent, child)
    if after is not None and hooks is not None and hooks.next is not None:
        hooks.next(key, t, after[1], args)
    if before is None:
        if after is not None and extrapolate:
            return _edge_pose(after)
        return None
    if after is None:
        if extrapolate:
            return _edge_pose(before)
        if hooks is not None and hooks.arrival is not None:
            hooks.arrival(key, t, args)
        return None
    return _interpolate(t, before[2], _edge_pose(before), after[1], _edge_pose(after))


def lookup(store: Any, tree: FrameTree, target: Any, source: Any, t: float,
           extrapolate: bool = False, hooks: TfHooks | None = None,
           check_deadline: Callable[[], None] | None = None) -> Pose | None:
    """The pose of frame ``source`` in frame ``target`` at time ``t`` (the transform that
    maps ``source`` coordinates into ``target``'s), or None when the frames are not
    connected or an edge has no value at ``t`` (see the module's text); :class:`PoseOverflow`
    when the chain's pose is beyond floats. ``check_deadline`` (raising when the query's
    time is up) is called every few edges: a long chain is one statement per edge.

    >>> from slr_sql.store import EventStore
    >>> s = EventStore(None)
    >>> s.add_events([("tf", ("map", "base", Struct("pose", ([1.0, 2.0, 0.0], [0.0, 0.0, 0.0, 1.0]))),
    ...                0.0, 0.0)])
    []
    >>> lookup(s, FrameTree(), "map", "base", 0.0)   # the pose of base in map
    ((1.0, 2.0, 0.0), (0.0, 0.0, 0.0, 1.0))
    >>> lookup(s, FrameTree(), "map", "base", 5.0), lookup(s, FrameTree(), "map", "base", 5.0, extrapolate=True)
    (None, ((1.0, 2.0, 0.0), (0.0, 0.0, 0.0, 1.0)))
    """
    if type(target) is str:
        target = Atom(target)
    if type(source) is str:
        source = Atom(source)
    if frame_key(target) == frame_key(source):
        return IDENTITY
    chain = tree.chain(store, target, source)
    if chain is None:
        return None
    result = IDENTITY
    kind, longest = tree.kind, tree.longest
    try:
        for i, (parent, child, inverse) in enumerate(chain):
            if check_deadline is not None and i % _EDGES_BETWEEN_CLOCK_CHECKS == 0:
                check_deadline()
            pair = (frame_key(parent), frame_key(child))
            step = _edge_at(store, kind[pair], parent, child, t, extrapolate, hooks,
                            longest.get(pair, 0.0))
            if step is None:
                return None
            result = compose(invert(step) if inverse else step, result)
    except _Unusable:
        return None
    if not all(math.isfinite(v) for v in result[0] + result[1]):
        raise PoseOverflow(f"the pose of {source} in {target} at {t!r} is beyond floats")
    return result
