"""Who may use the service: the bearer token (``slr serve --token`` / ``SLR_TOKEN``), checked
on every request but ``/health`` and ``/openapi.json`` and on a WebSocket's first message.

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
"""
from __future__ import annotations

import hmac

from slr_sql.errors import SLRError

from .errors import ServiceError

__all__ = ["BearerToken", "check_token_text"]

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


class BearerToken:
    """The check of one server's token; ``None`` (or empty): no check."""

    def __init__(self, token: str | None):
        self._token = check_token_text(token).encode("utf-8") if token else None

    @property
    def required(self) -> bool:
        return self._token is not None

    def __call__(self, header: str | None) -> None:
        """Pass when ``header`` (an ``Authorization`` value) is ``Bearer TOKEN``; else raise
        :class:`ServiceError` ``Unauthorized`` (401)."""
        if self._token is None:
            return
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
        if not hmac.compare_digest(given, self._token):
            raise ServiceError("a valid token is required (Authorization: Bearer TOKEN; "
                               "the server's --token or SLR_TOKEN)", kind="Unauthorized")
