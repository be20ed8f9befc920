"""The keys of the robots' completeness marks on a fleet store (``slr_meta``), in a module
of their own: the store's migrations rewrite them, and the shipping layer writes and reads
them.
"""
from __future__ import annotations

import re

__all__ = ["FLEET_MARK", "fleet_mark_key", "names_a_type", "read_fleet_mark_key"]

FLEET_MARK = "fleet/mark/"


def fleet_mark_key(robot: str, mark: str) -> str:
    """The ``slr_meta`` key of ``robot``'s completeness mark ``mark`` (``p/N`` or ``p/*``) on a
    fleet store: the robot's name with ``%`` and ``/`` escaped, so that no two robots' marks
    share a key whatever '/' their names and their types' names hold.

    >>> fleet_mark_key("r1/x", "seen/2"), fleet_mark_key("r1", "x/seen/2")
    ('fleet/mark/r1%2Fx/seen/2', 'fleet/mark/r1/x/seen/2')
    """
    return f"{FLEET_MARK}{robot.replace('%', '%25').replace('/', '%2F')}/{mark}"


_ESCAPED = re.compile("%(25|2F)")


def read_fleet_mark_key(key: str) -> tuple[str, str] | None:
    """``(robot, mark)`` of a key :func:`fleet_mark_key` wrote, or None for any other key.

    >>> read_fleet_mark_key("fleet/mark/r1%2Fx/seen/2"), read_fleet_mark_key("fleet/mark/r1/x/seen/2")
    (('r1/x', 'seen/2'), ('r1', 'x/seen/2'))
    >>> read_fleet_mark_key("fleet/mark/r1/seen") is None
    True
    """
    if not key.startswith(FLEET_MARK):
        return None
    robot, slash, mark = key[len(FLEET_MARK):].partition("/")
    if not slash or not names_a_type(mark):
        return None
    return _ESCAPED.sub(lambda m: "%" if m[1] == "25" else "/", robot), mark


def names_a_type(key: str) -> bool:
    """``p/2`` or ``p/*``: what a completeness mark is kept under.

    >>> names_a_type("seen/2"), names_a_type("a/b/*"), names_a_type("seen"), names_a_type("p/x")
    (True, True, False, False)
    """
    _, slash, arity = key.rpartition("/")
    return bool(slash) and (arity == "*" or (arity.isascii() and arity.isdigit()))
