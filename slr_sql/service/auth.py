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

from .errors import ServiceError

__all__ = ["BearerToken"]

SCHEME = "bearer "


class BearerToken:
    """The check of one server's token; ``None`` (or empty): no check."""

    def __init__(self, token: str | None):
        self._token = token.encode("utf-8", "surrogatepass") if token else None

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
            given = header[len(SCHEME):].strip().encode("utf-8", "surrogatepass")
        if not hmac.compare_digest(given, self._token):
            raise ServiceError("a valid token is required (Authorization: Bearer TOKEN; "
                               "the server's --token or SLR_TOKEN)", kind="Unauthorized")
