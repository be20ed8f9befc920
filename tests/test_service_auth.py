"""The service's token check (slr_sql/service/auth.py) on its own: exactly ``Bearer TOKEN``
passes; every near miss is a 401 ``Unauthorized``. (tests/test_service.py checks the same
through a real server, over HTTP and WebSocket.)"""
from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from slr_sql.errors import SLRError
from slr_sql.service.auth import BearerToken, RobotAccess, RobotToken, parse_robot_tokens
from slr_sql.service.errors import ServiceError

TOKEN = "s3cret"


@pytest.mark.parametrize("header", [f"Bearer {TOKEN}", f"bearer {TOKEN}", f"BEARER {TOKEN}",
                                    f"Bearer   {TOKEN}  ", f"Bearer {TOKEN}\t"])
def test_the_token_passes(header):
    assert BearerToken(TOKEN)(header) is None


@pytest.mark.parametrize("header", [
    None, "", "Bearer", "Bearer ", TOKEN, f"Basic {TOKEN}", f"Token {TOKEN}",
    f"Bearer {TOKEN}ANYTHING", f"Bearer {TOKEN[:-1]}", f"Bearer {TOKEN.upper()}",
    f"Bearer {TOKEN} {TOKEN}", f"Bearer{TOKEN}", f"Bearer x{TOKEN}", f"Bearer {TOKEN}\x00",
    f"XBearer {TOKEN}", f"Bearer {TOKEN[1:]}", "Bearer \ud800",
    # another seven-character scheme before the token: sorting below or above "bearer "
    f"Basic  {TOKEN}", f"Token  {TOKEN}", f"bearer_{TOKEN}", f"Bearer\t{TOKEN}",
])
def test_near_misses_are_refused_as_unauthorized(header):
    with pytest.raises(ServiceError) as info:
        BearerToken(TOKEN)(header)
    assert (info.value.kind, info.value.status) == ("Unauthorized", 401)
    assert "Authorization: Bearer TOKEN" in str(info.value)


@given(st.text(max_size=20))
def test_only_the_token_itself_passes(guess):
    check = BearerToken(TOKEN)
    if guess.strip() == TOKEN:
        check(f"Bearer {guess}")
    else:
        with pytest.raises(ServiceError):
            check(f"Bearer {guess}")


@pytest.mark.parametrize("token", [None, ""])
def test_no_token_lets_every_request_in(token):
    check = BearerToken(token)
    assert not check.required
    for header in (None, "", "Bearer anything", "garbage"):
        assert check(header) is None


def test_a_token_outside_ascii_is_compared_as_utf8():
    check = BearerToken("clé-ü")
    assert check.required
    check("Bearer clé-ü")
    with pytest.raises(ServiceError):
        check("Bearer cle-u")


# -- robot tokens (slr serve --robot-tokens) -------------------------------------------------

ROBOTS = [RobotToken("r1", "r1-token"), RobotToken("site", "site-token", frozenset({"r1"}))]


def test_a_robot_token_passes_as_its_robot_and_the_servers_own_token_as_before():
    check = BearerToken(TOKEN, ROBOTS)
    assert check(f"Bearer {TOKEN}") is None
    assert check("Bearer r1-token") == RobotAccess("r1")
    assert check("bearer  site-token ") == RobotAccess("site", frozenset({"r1"}))


@pytest.mark.parametrize("header", [
    "Bearer r1-toke", "Bearer r1-tokenX", "Bearer R1-TOKEN", "r1-token", "Basic r1-token",
    "Bearer r1-token site-token", "Bearer site-token" + TOKEN,
])
def test_near_misses_of_a_robot_token_are_refused_as_unauthorized(header):
    with pytest.raises(ServiceError) as info:
        BearerToken(TOKEN, ROBOTS)(header)
    assert (info.value.kind, info.value.status) == ("Unauthorized", 401)


@pytest.mark.parametrize("token, robots, words", [
    (None, ROBOTS[:1], "robot tokens need the server's own token"),
    (TOKEN, [RobotToken("r1", TOKEN, origin="t line 4")],
     "t line 4: the token of robot 'r1' is the server's own token"),
    (TOKEN, [RobotToken("r1", "hidden-1"), RobotToken("r2", "hidden-1", origin="t line 2")],
     "t line 2: the token of robot 'r2' is also the token of robot 'r1'"),
    (TOKEN, [RobotToken("r1", "hidden-1"), RobotToken("r1", "hidden-1")],
     "the token of robot 'r1' is also the token of robot 'r1'"),
])
def test_robot_tokens_that_cannot_stand_together_are_refused(token, robots, words):
    with pytest.raises(SLRError, match=words) as info:
        BearerToken(token, robots)
    assert "hidden" not in str(info.value) and TOKEN not in str(info.value)   # (secrets)


def test_a_robot_may_have_two_tokens_while_its_token_is_changed():
    check = BearerToken(TOKEN, [RobotToken("r1", "old"), RobotToken("r1", "new")])
    assert check("Bearer old") == check("Bearer new") == RobotAccess("r1")


def test_the_lines_of_a_robot_tokens_file():
    assert parse_robot_tokens("  # comment\n\nr1\ttok-1  \nsite tok-s relays r1 r2\n"
                              "#r9 tok-9\nforklift-ü tok-ü\n") == [
        RobotToken("r1", "tok-1"), RobotToken("site", "tok-s", frozenset({"r1", "r2"})),
        RobotToken("forklift-ü", "tok-ü")]
    with pytest.raises(SLRError, match=r"^f line 2: robot 'site' is named among the robots "
                                       r"it relays"):
        parse_robot_tokens("r1 a\nsite b relays r1 site", "f")
