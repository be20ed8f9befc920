"""The service's token check (slr_sql/service/auth.py) on its own: exactly ``Bearer TOKEN``
passes; every near miss is a 401 ``Unauthorized``. (tests/test_service.py checks the same
through a real server, over HTTP and WebSocket.)"""
from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from slr_sql.service.auth import BearerToken
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
