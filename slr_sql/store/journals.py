"""Subscriptions' storage: the registry of subscriptions (``slr_subscriptions``: definitions,
positions, claims) and the reads of delivery (journals and histories).

:class:`SubscriptionTables` runs on the store's connection, inside its transactions.
:class:`JournalReader` runs the reading statements of delivery on one connection: the
store's (which waits for a writer's commit) or a connection of its own (which does not: a
lagging subscriber's reads then never queue behind, nor delay, the writers). Journals
themselves are created and dropped by :meth:`Catalog.create_journal` / ``drop_journal``.

>>> from slr_sql.store import EventStore
>>> s = EventStore(None); s.add_event("p", ("a",), 1, 1)
>>> s.create_journal("p", 1, "slr_subj_p", "slr_subt_p"); s.add_event("p", ("b",), 2, 2)
>>> reads = s.journal_reader(own_connection=False)
>>> reads.journal_rows("slr_subj_p", 1, 0, 10), reads.max_jid("slr_subj_p")
([(1, 2, 'b', 2.0, 2.0)], 1)
"""
from __future__ import annotations

import functools
import sqlite3
import json
from collections.abc import Callable, Iterable
from typing import Any, NamedTuple

from .sqltext import quote_identifier

__all__ = ["SubscriptionRecord", "SubscriptionTables", "JournalReader", "stored_text", "read_text"]

_COLUMNS = ("id", "durable", "pattern", "where_goal", "since", "until", "type_name",
            "type_arity", "history_done", "live_pos", "finished", "owner", "lease_until")


class SubscriptionRecord(NamedTuple):
    """What ``slr_subscriptions`` holds of one subscription to resume it."""

    pattern: str
    where_goal: str | None
    since: float
    until: float | None
    history_top: int
    history_pos: int
    history_done: int
    live_start: int
    live_pos: int
    finished: int
    owner: str | None
    lease_until: float | None


# A store whose text cannot hold U+0000 (PostgreSQL) keeps a subscription's id, pattern,
# condition or type name holding one as its JSON after this mark, and a text beginning with
# the mark too, so that every text reads back as itself: a subscription to events with a
# U+0000 in an atom (which such a store holds, escaped) is taken as on SQLite
_ESCAPED = "\x01"


def stored_text(value: str | None, holds_nul: bool) -> str | None:
    """``value`` as a store whose text holds U+0000 or not (``holds_nul``) keeps it.

    >>> stored_text("cam(X)^T", False), stored_text("a\\x00b", False) == '\\x01"a\\\\u0000b"'
    ('cam(X)^T', True)
    >>> read_text(stored_text("p('a\\x00b')^T", False), False) == "p('a\\x00b')^T"
    True
    """
    if value is None or holds_nul or ("\x00" not in value and not value.startswith(_ESCAPED)):
        return value
    return _ESCAPED + json.dumps(value)


def read_text(value: str | None, holds_nul: bool) -> str | None:
    """The text :func:`stored_text` kept as ``value``.

    >>> read_text('\\x01"a\\\\u0000"', False) == "a\\x00", read_text("cam", False)
    (True, 'cam')
    """
    if value is None or holds_nul or not value.startswith(_ESCAPED):
        return value
    try:
        text = json.loads(value[1:])
    except ValueError:   # (a row written before the mark was: the text itself)
        return value
    return text if isinstance(text, str) else value


class SubscriptionTables:
    """The registry of subscriptions on the store's connection (every write inside the
    caller's transaction, or one of its own)."""

    def __init__(self, db: Any):
        self.db = db
        holds_nul = bool(getattr(getattr(db, "dialect", None), "text_holds_nul", True))
        self._in = functools.partial(stored_text, holds_nul=holds_nul)
        self._out = functools.partial(read_text, holds_nul=holds_nul)

    def _run(self, sql: str, params: Iterable[Any] = ()) -> list[tuple]:
        # (the registry's callers -- the hub's housekeeping and delivery threads among
        # them -- expect an SLRError: a journal or registry table another connection
        # dropped is said in words, as the journal reader says it, not as a raw
        # database error, which their logs would print with a traceback)
        try:
            return self.db.execute(sql, params)
        except sqlite3.Error as exc:
            raise self.db.read_error(exc) from None

    def subscription_wanted(self, name: str, arity: int) -> bool:
        """Does an unfinished subscription (of any process) want event type name/arity?"""
        return bool(self._run(
            "SELECT 1 FROM slr_subscriptions WHERE type_name = ? AND type_arity = ? "
            "AND finished = 0 LIMIT 1", (self._in(name), arity)))

    def subscription_record(self, sub_id: str) -> SubscriptionRecord | None:
        """The stored definition and position of subscription ``sub_id``, if any."""
        rows = self._run(
            "SELECT pattern, where_goal, since, until, history_top, history_pos, "
            "history_done, live_start, live_pos, finished, owner, lease_until "
            "FROM slr_subscriptions WHERE id = ?", (self._in(sub_id),))
        if not rows:
            return None
        pattern, where_goal, *position = rows[0]
        return SubscriptionRecord(self._out(pattern), self._out(where_goal), *position)

    def insert_subscription(self, sub_id: str, durable: bool, pattern: str,
                            where_goal: str | None, since: float, until: float | None,
                            type_name: str, type_arity: int, history_top: int,
                            live_start: int, owner: str, lease_until: float,
                            created_at: float) -> None:
        """Register a new subscription: its history is the type's rows up to ``history_top``
        (done already when 0), its live events the journal rows after ``live_start``."""
        self._run(
            "INSERT INTO slr_subscriptions (id, durable, pattern, where_goal, since, "
            "until, type_name, type_arity, history_top, history_pos, history_done, "
            "live_start, live_pos, finished, owner, lease_until, created_at) "
            "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, 0, ?, ?, ?, 0, ?, ?, ?)",
            (self._in(sub_id), int(durable), self._in(pattern), self._in(where_goal), since,
             until, self._in(type_name), type_arity,
             history_top, int(history_top == 0), live_start, live_start, owner, lease_until,
             created_at))

    def claim_subscription(self, sub_id: str, owner: str, lease_until: float) -> None:
        """Make ``owner`` (a process) the deliverer of ``sub_id`` until ``lease_until``."""
        self._run("UPDATE slr_subscriptions SET owner = ?, lease_until = ? WHERE id = ?",
                  (owner, lease_until, self._in(sub_id)))

    def delete_subscription(self, sub_id: str, owner: str | None = None) -> bool:
        """Remove ``sub_id`` (only while ``owner`` holds it, when given); False if there was
        no such row."""
        sub_id = self._in(sub_id)
        if owner is None:
            if not self._run("SELECT 1 FROM slr_subscriptions WHERE id = ?", (sub_id,)):
                return False
            self._run("DELETE FROM slr_subscriptions WHERE id = ?", (sub_id,))
            return True
        self._run("DELETE FROM slr_subscriptions WHERE id = ? AND owner = ?", (sub_id, owner))
        return True

    def write_subscription_position(self, sub_id: str, owner: str, history_done: int,
                                    history_pos: int, live_pos: int, finished: bool,
                                    lease_until: float | None,
                                    new_owner: str | None) -> None:
        """Move the stored position of ``sub_id`` (held by ``owner``) forward, never back;
        ``new_owner`` None with ``lease_until`` None releases the claim."""
        self._run(
            "UPDATE slr_subscriptions SET history_done = ?, history_pos = ?, live_pos = ?, "
            "finished = CASE WHEN ? = 1 THEN 1 ELSE finished END, lease_until = ?, owner = ? "
            "WHERE id = ? AND owner = ? AND (history_done < ? OR (history_done = ? AND "
            "history_pos <= ? AND live_pos <= ?))",
            (history_done, history_pos, live_pos, int(finished), lease_until, new_owner,
             self._in(sub_id), owner, history_done, history_done, history_pos, live_pos))

    def renew_subscriptions(self, owner: str, lease_until: float) -> set[str]:
        """Extend every claim of ``owner``; the ids it still holds."""
        self._run("UPDATE slr_subscriptions SET lease_until = ? WHERE owner = ?",
                  (lease_until, owner))
        return {self._out(r[0]) for r in self._run(
            "SELECT id FROM slr_subscriptions WHERE owner = ?", (owner,))}

    def expire_subscriptions(self, now_wall: float) -> None:
        """Remove the non-durable subscriptions whose claim ran out (their process died)."""
        self._run("DELETE FROM slr_subscriptions WHERE durable = 0 AND lease_until < ?",
                  (now_wall,))

    def live_positions(self, name: str, arity: int) -> list[tuple[str, str | None, int]]:
        """``(id, owner, live_pos)`` of every unfinished subscription of name/arity."""
        return [(self._out(r[0]), r[1], r[2]) for r in self._run(
            "SELECT id, owner, live_pos FROM slr_subscriptions WHERE type_name = ? AND "
            "type_arity = ? AND finished = 0", (self._in(name), arity))]

    def trim_journal(self, journal: str, through_jid: int) -> None:
        """Delete the rows of ``journal`` up to ``through_jid`` (every subscription is past
        them)."""
        # (with the schema, as every statement here names a journal: another process may
        # have dropped it, and the name alone would reach a temporary table of the session)
        self._run(f"DELETE FROM {self.db.qualified(journal)} WHERE jid <= ?", (through_jid,))

    def subscription_rows(self) -> list[dict[str, Any]]:
        """Every registered subscription, as dicts, by id."""
        rows = self._run(f"SELECT {', '.join(_COLUMNS)} FROM slr_subscriptions ORDER BY id")
        out = [dict(zip(_COLUMNS, row)) for row in rows]
        for row in out:
            for column in ("id", "pattern", "where_goal", "type_name"):
                row[column] = self._out(row[column])
        return out

    def journal_start(self, table: str, journal: str) -> tuple[int, int]:
        """``(greatest seq of table, greatest jid of journal)``, 0 when empty: where a new
        subscription's history ends and its live events begin."""
        top = self._run(f"SELECT coalesce(max(seq), 0) FROM {self.db.qualified(table)}")[0][0]
        start = self._run(f"SELECT coalesce(max(jid), 0) FROM "
                          f"{self.db.qualified(journal)}")[0][0]
        return top, start


class _Statements(NamedTuple):
    history: str
    history_by_end: str
    window_count: str
    journal: str
    max_jid: str


@functools.lru_cache(maxsize=1024)
def _statements(t: str, j: str, arity: int) -> _Statements:
    """The statements of table ``t`` and journal ``j`` (named as :meth:`Database.qualified`
    names them)."""
    cols = "".join(f", arg{i}" for i in range(1, arity + 1))
    tcols = "".join(f", t.arg{i}" for i in range(1, arity + 1))
    history = (
        f"SELECT t.seq{tcols}, t.t_start, t.t_end FROM {t} AS t "
        f"WHERE t.seq > ? AND t.seq <= ? AND t.t_end >= ? AND t.t_end <= ? "
        f"AND NOT EXISTS (SELECT 1 FROM {j} AS j WHERE j.seq = t.seq AND j.jid > ?) "
        f"ORDER BY t.seq LIMIT ?")
    # few events in [since, until] (e.g. since="now" on a long history): read them through
    # the end-time index and sort them, rather than walking every row by seq
    by_end = history.replace("WHERE t.seq > ? AND t.seq <= ?",
                             "WHERE +t.seq > ? AND +t.seq <= ?")
    return _Statements(
        history, by_end,
        f"SELECT count(*) FROM (SELECT 1 FROM {t} WHERE t_end >= ? AND t_end <= ? "
        f"LIMIT ?) AS w",
        f"SELECT jid, seq{cols}, t_start, t_end FROM {j} WHERE jid > ? ORDER BY jid LIMIT ?",
        f"SELECT max(jid) FROM {j}")


class JournalReader:
    """The reading statements of subscription delivery, on one connection (``execute``):
    a journal's rows after a position, a history window, counts and heads. Made by
    :meth:`EventStore.journal_reader`."""

    def __init__(self, execute: Callable[[str, tuple], list[tuple]],
                 close: Callable[[], None] | None = None,
                 qualified: Callable[[str], str] = quote_identifier):
        self._execute = execute
        self._close = close
        # how a table or journal is named: with the store's schema on PostgreSQL
        # (Database.qualified)
        self._name = qualified

    def journal_rows(self, journal: str, arity: int, after_jid: int,
                     limit: int) -> list[tuple]:
        """``(jid, seq, arg1.., t_start, t_end)`` of the journal rows after ``after_jid``,
        in jid order, ``limit`` at most."""
        return self._execute(_statements("", self._name(journal), arity).journal,
                             (after_jid, limit))

    def history_rows(self, table: str, journal: str, arity: int, after_seq: int,
                     top_seq: int, since: float, until: float, live_start: int, limit: int,
                     by_end: bool) -> list[tuple]:
        """``(seq, arg1.., t_start, t_end)`` of the stored rows with ``after_seq < seq <=
        top_seq`` ending in [since, until], in seq order, ``limit`` at most, leaving out the
        rows the journal holds after ``live_start`` (delivered live). ``by_end``: walk the
        end-time index (few rows in the window) rather than the table by seq."""
        s = _statements(self._name(table), self._name(journal), arity)
        return self._execute(s.history_by_end if by_end else s.history,
                             (after_seq, top_seq, since, until, live_start, limit))

    def window_count(self, table: str, since: float, until: float, cap: int) -> int:
        """How many rows of ``table`` end in [since, until], counted up to ``cap`` at most."""
        return self._execute(_statements(self._name(table), "", 0).window_count,
                             (since, until, max(cap, 0)))[0][0]

    def event_table(self, name: str, arity: int) -> str | None:
        """The table of event type name/arity as committed (None while it has none)."""
        rows = self._execute("SELECT table_name FROM slr_event_types WHERE name = ? AND "
                             "arity = ?", (name, arity))
        return rows[0][0] if rows else None

    def max_jid(self, journal: str) -> int:
        """The greatest jid of ``journal`` (0 when empty)."""
        return self._execute(_statements("", self._name(journal), 0).max_jid, ())[0][0] or 0

    def close(self) -> None:
        """Close the connection when it is the reader's own (idempotent)."""
        if self._close is not None:
            self._close()
