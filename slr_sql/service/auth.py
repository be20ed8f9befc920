"""Who may use the service: the bearer token (``slr serve --token`` / ``SLR_TOKEN``), checked
on every request but ``/health`` and ``/openapi.json`` and on a WebSocket's first message;
and the tokens of robots (``slr serve --robot-tokens FILE``), each of which lets its robot
ship to a fleet store as itself and do nothing else (docs/fleet.md, "Robot tokens").

The whole token is compared, in constant time (``hmac.compare_digest`` on the UTF-8 bytes):
a prefix, a longer text, another case or another scheme is refused alike, and the time the
check takes does not say how much of a guess was right.

>>> check = BearerToken("s3cret")
>>> check("Bearer s3cret"), check("bearer s3cret")
(None, None)
>>> check("Bearer s3cretANYTHING")
Traceback (most recent call last):
...
slr_sql.service.errors.ServiceError: a valid token is required (Authorization: Bearer TOKEN; the server's --token or SLR_TOKEN)
>>> BearerToken(None)(None) is None     # no token: every request is let in
True
>>> robots = BearerToken("s3cret", [RobotToken("r1", "r1-token")])
>>> robots("Bearer s3cret") is None, robots("Bearer r1-token")     # full access; robot r1's
(True, RobotAccess(robot='r1', relays=frozenset()))
"""
from __future__ import annotations

import hmac
from dataclasses import dataclass, field
from typing import Iterable

from slr_sql.errors import SLRError

from .errors import ServiceError

__all__ = ["BearerToken", "RobotAccess", "RobotToken", "check_token_text",
           "parse_robot_tokens", "read_robot_tokens"]

SCHEME = "bearer "


def check_token_text(token: str) -> str:
    """``token`` if an ``Authorization`` header can carry it whole: no control character (a
    line break would end the header), no lone surrogate, no space at either end (the server
    reads the header's value stripped); else an :class:`~slr_sql.SLRError` saying why (without
    the token, which is a secret). A server given another token could never be reached, and
    a client could never send it. Text beyond ASCII travels as its UTF-8 bytes.

    >>> check_token_text("s3cret-clé")
    's3cret-clé'
    >>> check_token_text("tab" + chr(9) + "in it")
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: a token cannot hold a control character (an HTTP header cannot carry it); this one holds '\\t'
    """
    bad = next((c for c in token if c < " " or "\x7f" <= c <= "\x9f"
                or "\ud800" <= c <= "\udfff"), None)
    if bad is not None:
        kind = "a lone surrogate" if bad >= "\ud800" else "a control character"
        raise SLRError(f"a token cannot hold {kind} (an HTTP header cannot carry it); this one "
                       f"holds {bad!a}")
    if token != token.strip():
        raise SLRError("a token has no space at its start or end (the header's value is read "
                       "without them)")
    return token


@dataclass(frozen=True)
class RobotAccess:
    """What a request bearing a robot's token may do: ship to the fleet store as ``robot``
    (``GET /fleet/positions`` and ``POST /fleet/receive`` of that robot), bringing rows and
    marks of its own and of the robots in ``relays`` (a site store relaying its robots')."""

    robot: str
    relays: frozenset = frozenset()

    def may_bring(self, robot: str) -> bool:
        """Whether a shipment of this token may carry rows or marks of ``robot``.

        >>> site = RobotAccess("site", frozenset({"r1"}))
        >>> site.may_bring("site"), site.may_bring("r1"), site.may_bring("r2")
        (True, True, False)
        """
        return robot == self.robot or robot in self.relays


@dataclass(frozen=True)
class RobotToken:
    """One robot token of a server: ``robot`` ships with ``token`` (and relays the robots of
    ``relays``). ``origin`` says where it was written (``FILE line N``), for the messages
    that refuse it; the token itself is never shown.

    >>> RobotToken("r1", "r1-token")
    RobotToken(robot='r1', relays=frozenset())
    """

    robot: str
    token: str = field(repr=False)
    relays: frozenset = frozenset()
    origin: str = field(default="", repr=False, compare=False)

    @property
    def access(self) -> RobotAccess:
        return RobotAccess(self.robot, self.relays)


RELAYS = "relays"   # the word before the robots a token relays, on a --robot-tokens line


def parse_robot_tokens(text: str, source: str = "robot tokens") -> list[RobotToken]:
    """The robot tokens of the text of a ``--robot-tokens`` file (``source``: its name, for
    the messages). A line is ``ROBOT TOKEN``, or ``ROBOT TOKEN relays ROBOT...`` for a
    store that relays the rows of other robots (a site store its robots'); fields are
    separated by white space (so neither a name nor a token holds any); a line whose first
    field starts with ``#`` is a comment, and an empty line is skipped. A line that is none of
    these is an :class:`~slr_sql.SLRError` naming its line (never its token). Which tokens
    may stand together (no token twice, none the server's own) is :class:`BearerToken`'s to
    say.

    >>> parse_robot_tokens("# robot token\\nr1 tok-1\\nsite tok-s relays r1\\n")
    [RobotToken(robot='r1', relays=frozenset()), RobotToken(robot='site', relays=frozenset({'r1'}))]
    >>> parse_robot_tokens("r1", "tokens.txt")
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: tokens.txt line 1: a robot token line is 'ROBOT TOKEN' or 'ROBOT TOKEN relays ROBOT...'; this one has no token
    """
    from slr_sql.store import check_robot_name

    out = []
    for number, line in enumerate(text.splitlines(), 1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        where = f"{source} line {number}"
        usage = (f"{where}: a robot token line is 'ROBOT TOKEN' or 'ROBOT TOKEN {RELAYS} "
                 "ROBOT...'; this one")
        if len(fields) < 2:
            raise SLRError(f"{usage} has no token")
        if len(fields) > 2 and fields[2] != RELAYS:
            raise SLRError(f"{usage} has {len(fields) - 2} more field(s) after the token "
                           f"without '{RELAYS}' before them (a token holds no white space)")
        if len(fields) == 3:
            raise SLRError(f"{usage} names no robot after '{RELAYS}'")
        robot, token, relayed = fields[0], fields[1], fields[3:]
        try:
            check_robot_name(robot)
            for name in relayed:
                check_robot_name(name)
            check_token_text(token)
        except SLRError as exc:
            raise SLRError(f"{where}: {exc}") from None
        if robot in relayed:
            raise SLRError(f"{where}: robot {robot!r} is named among the robots it relays "
                           "(its own rows and marks go with its token anyway)")
        out.append(RobotToken(robot, token, frozenset(relayed), where))
    return out


def read_robot_tokens(path: str) -> list[RobotToken]:
    """The robot tokens of the file ``path`` (:func:`parse_robot_tokens`): what ``slr serve
    --robot-tokens FILE`` reads once, at its start. A file that cannot be read, is not UTF-8
    text or holds no token is an :class:`~slr_sql.SLRError` saying so.

    >>> import os, tempfile; path = os.path.join(tempfile.mkdtemp(), "tokens")
    >>> _ = open(path, "w").write("r1 tok-1")
    >>> read_robot_tokens(path)
    [RobotToken(robot='r1', relays=frozenset())]
    >>> read_robot_tokens(path + "-missing")
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: cannot read the robot tokens ...tokens-missing: No such file or directory
    """
    try:
        with open(path, "rb") as handle:
            data = handle.read()
    except OSError as exc:
        raise SLRError(f"cannot read the robot tokens {path}: {exc.strerror or exc}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SLRError(f"the robot tokens {path} are not UTF-8 text (byte {exc.start})") \
            from None
    tokens = parse_robot_tokens(text, path)
    if not tokens:
        raise SLRError(f"the robot tokens {path} hold no token (a line is 'ROBOT TOKEN')")
    return tokens


class BearerToken:
    """The check of one server's token; ``None`` (or empty): no check. ``robots``: the
    tokens of robots (:class:`RobotToken`), which need the server's token beside them (without
    one every request has full access) and must each differ from it and from one another."""

    def __init__(self, token: str | None, robots: Iterable[RobotToken] = ()):
        self._token = check_token_text(token).encode("utf-8") if token else None
        self._robots: list[tuple[bytes, RobotAccess]] = []
        seen: dict[bytes, RobotToken] = {}
        for entry in robots:
            where = f"{entry.origin}: " if entry.origin else ""
            if self._token is None:
                raise SLRError("robot tokens need the server's own token beside them (--token "
                               "or SLR_TOKEN): without one every request has full access, and "
                               "a robot's token would restrict nothing")
            secret = check_token_text(entry.token).encode("utf-8")
            if hmac.compare_digest(secret, self._token):
                raise SLRError(f"{where}the token of robot {entry.robot!r} is the server's "
                               "own token: it would give the robot full access; give each robot a "
                               "token of its own")
            other = seen.get(secret)
            if other is not None:
                said = f" ({other.origin})" if other.origin else ""
                raise SLRError(f"{where}the token of robot {entry.robot!r} is also the token "
                               f"of robot {other.robot!r}{said}: the server could not tell them apart; "
                               "give each robot a token of its own")
            seen[secret] = entry
            self._robots.append((secret, entry.access))

    @property
    def required(self) -> bool:
        return self._token is not None

    @property
    def robots(self) -> bool:
        """Whether robot tokens are given (a shipment's robot can then be told apart)."""
        return bool(self._robots)

    def __call__(self, header: str | None) -> RobotAccess | None:
        """Pass when ``header`` (an ``Authorization`` value) is ``Bearer TOKEN``, with None
        (full access), or when it bears a robot's token, with that robot's
        :class:`RobotAccess`; else raise :class:`ServiceError` ``Unauthorized`` (401). Each
        token is compared whole in constant time: the server's first, then every robot's (a
        guess costs the same whichever it nearly matches)."""
        if self._token is None:
            return None
        given = b""
        if header and header[:len(SCHEME)].lower() == SCHEME:
            text = header[len(SCHEME):].strip()
            try:
                # the server decodes a header's bytes as ISO-8859-1: these are the bytes the
                # client sent, which hold a token beyond ASCII as UTF-8
                text = text.encode("latin-1").decode("utf-8")
            except UnicodeError:
                pass        # (not bytes of UTF-8: compared as they are)
            given = text.encode("utf-8", "surrogatepass")
        if hmac.compare_digest(given, self._token):
            return None
        found = None
        for secret, access in self._robots:
            # (no early end: the time does not say which robot's token a guess was near)
            if hmac.compare_digest(given, secret):
                found = access
        if found is None:
            raise ServiceError("a valid token is required (Authorization: Bearer TOKEN; "
                               "the server's --token or SLR_TOKEN)", kind="Unauthorized")
        return found
