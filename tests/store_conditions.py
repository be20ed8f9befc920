"""Conditions of a store's file met for real, for the tests of how each is said: the error
an SLRError must be, and a file damaged (or replaced) under an open store."""
from __future__ import annotations

import os
import sqlite3
from typing import Any, Callable

import pytest

from slr_sql.errors import SLRError, SLRStoreGone


def slr_failure(call: Callable[[], Any]) -> SLRError:
    """What ``call()`` raises: an SLRError in words, no sqlite3 error, none chained."""
    with pytest.raises(Exception) as caught:
        call()
    exc = caught.value
    assert isinstance(exc, SLRError), f"{type(exc).__name__}: {exc}"
    assert not isinstance(exc, sqlite3.Error)
    assert exc.__cause__ is None and (exc.__context__ is None or exc.__suppress_context__)
    return exc


def file_condition(path: str, handle: Any, read: Callable[[Any], Any], afterwards: str,
                   make_store: Callable[[str], Any]) -> SLRError:
    """``read(handle)`` works; then the file's bytes turn to garbage under ``handle`` (an open
    store or connection, its cached pages dropped) and, ``afterwards == "replaced"``, another
    store (``make_store``) takes its place at the path: the error ``read`` meets then, a
    damaged file or SLRStoreGone, checked and returned."""
    read(handle)
    with open(path, "r+b") as f:    # the whole file, header included
        f.write(b"\xff" * os.path.getsize(path))
    handle.execute("PRAGMA shrink_memory")   # the next read reads the file
    if afterwards == "replaced":
        other = path + ".other"
        make_store(other).close()
        os.replace(other, path)
    exc = slr_failure(lambda: read(handle))
    if afterwards == "damaged":
        assert type(exc) is SLRError
        # (not a database; or, where the header was read before, a malformed page)
        assert str(exc).startswith(f"{path}: the file is damaged ("), exc
    else:
        assert isinstance(exc, SLRStoreGone)
        assert str(exc).startswith(f"{path}: the store file was deleted or replaced while "
                                   f"open"), exc
    return exc
