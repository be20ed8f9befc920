"""``slr``: the command line, a thin layer over the library API (README.md, "Command line").

Every command opens the store with :func:`slr_sql.open`, does one thing through the public
API and closes it.  Errors: a :class:`slr_sql.SLRSyntaxError` prints its own text
(``file:line:col: message``, the source line and a caret) on stderr; an ISO error raised by a
goal prints in words (``error: unknown procedure nosuch/1``); any other error prints
``error: message``; all exit with status 1, never with a traceback.  Only ``load``, ``add``,
``ingest``, ``run``, ``demo`` and ``serve`` create a store; the other commands on a missing
path or an empty file say ``no such store: PATH``.
"""
from __future__ import annotations

import json
import math
import os
import re
import sys
import warnings
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Iterator

import click

import slr_sql

from .api import KnowledgeBaseAPI
from .answers import answer_text, unnamed_variables_named, value_text
from .encoding import decode
from .arguments import check_time_option
from .errors import STOPPED_BY_CALLER
from .kb import KnowledgeBase, Solutions
from .parser import full_stop_end, parse_event_fast, parse_indicator
from .printable import printable_name, printable_syntax_error, printable_text
from .arguments import refuse_memory_store
from .store import refuse_no_store, shown_location
from .terms import Atom, Struct, list_items

__all__ = ["main", "parse_event_line", "ingest_file", "IngestReport", "strip_full_stop"]

INGEST_BATCH = 5000        # events per kb.add_many transaction (each one is fsynced)
PROGRESS_MIN_BYTES = 256_000  # files smaller than this ingest without a progress bar


def _err(message: str) -> None:
    # messages quote names from stores, files and requests: escaped, never raw (printable.py)
    click.echo(printable_text(message), err=True)


def _iso_words(term: Any) -> str | None:
    """An ISO error term ``error(Formal, Context)`` in words, as a Prolog top level says it
    (``unknown procedure nosuch/1``); None for a term that is not one."""
    if not (isinstance(term, Struct) and term.name == "error" and len(term.args) == 2):
        return None
    formal = term.args[0]
    name = str(formal.name) if isinstance(formal, Struct) else str(formal)
    args = [value_text(a) for a in formal.args] if isinstance(formal, Struct) else []
    evaluation = {"zero_divisor": "division by zero", "undefined": "undefined result",
                  "float_overflow": "float overflow", "int_overflow": "integer overflow",
                  "float_underflow": "float underflow"}
    if name == "instantiation_error":
        return "arguments are not sufficiently instantiated"
    if name == "existence_error" and len(args) == 2:
        if args[0] == "procedure":
            return f"unknown procedure {args[1]}"
        return f"{args[0]} does not exist: {args[1]}"
    if name == "type_error" and len(args) == 2:
        return f"type error: expected {args[0]}, found {args[1]}"
    if name == "domain_error" and len(args) == 2:
        return f"domain error: expected {args[0]}, found {args[1]}"
    if name == "evaluation_error" and len(args) == 1:
        return f"arithmetic: {evaluation.get(args[0], args[0])}"
    if name == "representation_error" and len(args) == 1:
        return f"cannot represent {args[0]}"
    if name == "resource_error" and len(args) == 1:
        return f"out of {args[0]}"
    if name == "permission_error" and len(args) == 3:
        return f"permission error: cannot {args[0]} {args[1]} {args[2]}"
    if name == "syntax_error" and len(args) == 1:
        return f"syntax error: {args[0]}"
    if name == "uninstantiation_error" and len(args) == 1:
        return f"expected an unbound variable, found {args[0]}"
    return None


def error_words(exc: BaseException) -> str:
    """What the command line prints for an error (without the ``error:`` prefix): an ISO
    error term in words, a database error with what it is, anything else as its message.

    >>> from slr_sql import open as open_kb
    >>> try:
    ...     open_kb().query("nosuch(1)")
    ... except slr_sql.SLRError as exc:
    ...     print(error_words(exc))
    unknown procedure nosuch/1
    """
    if isinstance(exc, slr_sql.SLREvaluationError):
        term = getattr(exc, "term", None)
        words = _iso_words(term)
        if words is not None:
            # The library's hint after the term (``color/2 is defined with ^T: did you
            # mean color(cup2, C)^T?``) is for the user too.
            message = str(exc)
            if message.startswith("error(") and "): " in message:
                words += "; " + message.split("): ", 1)[1]
            return words
    from .store import DatabaseError

    if isinstance(exc, DatabaseError):
        return f"database: {exc}"
    if isinstance(exc, slr_sql.SLRError):
        return str(exc)
    return f"{type(exc).__name__}: {exc} (this is a bug in slr_sql; please report it)"


_SENTENCE_END = re.compile(r"(?<!e\.g)(?<!i\.e)(?<!etc)\.(?=\s|$)")


def one_liner(command: click.Command) -> str:
    """A command's line in ``slr --help``: its ``short_help``, or the first sentence of its
    help, whole (click would cut it at 45 characters, or at the "." of "e.g.").

    >>> one_liner(click.Command("x", help="Run a SQL STATEMENT, e.g. SELECT 1. More."))
    'Run a SQL STATEMENT, e.g. SELECT 1.'
    """
    if command.short_help:
        return command.short_help
    paragraph = (command.help or "").split("\n\n")[0]
    text = " ".join(paragraph.replace("\b", "").split())
    end = _SENTENCE_END.search(text)
    return text[:end.end()] if end else text


class SLRGroup(click.Group):
    """Turns every error into the CLI's error contract (words, exit 1) instead of a
    traceback; click's own usage errors and exits pass through.

    The commands in :data:`LAZY_COMMANDS` are imported when first asked for: by name, by
    ``--help`` (which lists every command) or by a name that is none (click's "Did you mean"
    picks from every command)."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted({*self.commands, *LAZY_COMMANDS})

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name not in self.commands:
            for name in [cmd_name] if cmd_name in LAZY_COMMANDS else list(LAZY_COMMANDS):
                if name not in self.commands:
                    command = LAZY_COMMANDS[name]()
                    _whole_one_liners(command)
                    self.add_command(command, name)
        return super().get_command(ctx, cmd_name)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = []
        for name in self.list_commands(ctx):
            command = self.get_command(ctx, name)
            if command is not None and not command.hidden:
                rows.append((name, one_liner(command)))
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except slr_sql.SLRSyntaxError as exc:
            _err(printable_syntax_error(exc))
            ctx.exit(1)
        except (click.exceptions.ClickException, click.exceptions.Exit,
                click.exceptions.Abort):
            raise
        except RecursionError:
            _err("error: the term is nested too deeply")
            ctx.exit(1)
        except MemoryError:
            # an input larger than memory (`slr ingest DB /dev/zero`: one endless line), a
            # goal that builds too much: no bug of slr_sql, and its message is empty
            _err("error: out of memory (an input line, a file or an answer larger than this "
                 "process may hold)")
            ctx.exit(1)
        except BrokenPipeError as exc:
            # the reader of the output left (`slr sql DB ... | head -1`): no word on standard
            # error (it was "error: BrokenPipeError ... this is a bug in slr_sql"), exit 1 as
            # Python's own recipe and rich's tables do (`slr ros info BAG | head -1`)
            if not standard_output_gone():
                _err(f"error: {error_words(exc)}")
            ctx.exit(1)
        except Exception as exc:  # SLRError, a database error, or a bug: words, exit 1
            _err(f"error: {error_words(exc)}")
            ctx.exit(1)


def standard_output_gone() -> bool:
    """Whether standard output is a pipe whose reader closed it (``| head`` read its
    lines). If so, standard output is pointed at the null device, so that the interpreter's
    last flush of what is buffered finds no closed pipe (it printed "Exception ignored ...
    BrokenPipeError" after the command had ended).

    >>> standard_output_gone()
    False
    """
    import select

    try:
        fd = sys.stdout.fileno()
        poller = select.poll()
        poller.register(fd, select.POLLOUT)
        gone = any(events & select.POLLERR for _, events in poller.poll(0))
    except (OSError, ValueError, AttributeError):
        return False
    if gone:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, fd)
        os.close(null)
    return gone


def strip_full_stop(text: str) -> str:
    """``"color(cup1,C)^5."`` -> ``"color(cup1,C)^5"``: goals are accepted with or without the
    Prolog full stop, but a trailing ``..`` (as in ``=..``) is not a full stop.

    >>> strip_full_stop("color(cup1,C)^5. "), strip_full_stop("X =.. [f,1]"), strip_full_stop("T = ..")
    ('color(cup1,C)^5', 'X =.. [f,1]', 'T = ..')
    """
    text = text.strip()
    if text.endswith(".") and not text.endswith(".."):
        text = text[:-1].rstrip()
    return text


def _is_url(db: str) -> bool:
    return db.startswith(("http://", "https://"))


def _open(db: str, create: bool = True) -> KnowledgeBaseAPI:
    """The knowledge base in DB: a file opened in this process (only commands that add to a
    store may create it), or the URL of a running `slr serve`."""
    if _is_url(db):
        ctx = click.get_current_context(silent=True)
        token = (ctx.find_root().obj or {}).get("token") if ctx is not None else None
        return slr_sql.connect(db, token=token)
    _check_existing_store(db, create)
    if create:
        refuse_memory_store(db, _command_name())
    return slr_sql.open(db)


def _command_name() -> str:
    """``slr add``, ``slr fleet push``: the command running, as a person types it."""
    ctx = click.get_current_context(silent=True)
    names = []
    while ctx is not None and ctx.parent is not None:
        names.append(ctx.info_name or "")
        ctx = ctx.parent
    return " ".join(["slr", *reversed(names)])


def _check_existing_store(db: str, create: bool = False) -> None:
    """Commands that do not add to a store never create one: neither from a missing path nor
    from an empty file (SQLite would make an empty file a database on the first write)."""
    if not create:
        refuse_no_store(db)


def _existing_file(path: str) -> str:
    """``path`` if it is a readable file, else an SLRError in words (exit 1, not click's
    usage error)."""
    if not os.path.exists(path):
        raise slr_sql.SLRError(f"no such file: {path}")
    if os.path.isdir(path):
        raise slr_sql.SLRError(f"{path}: is a directory, not a file")
    return path


@click.group(cls=SLRGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(version=slr_sql.__version__, prog_name="slr")
@click.option("--token", envvar="SLR_TOKEN", default=None,
              help="Token for a DB given as the URL of `slr serve` (default: $SLR_TOKEN).")
@click.pass_context
def main(ctx: click.Context, token: str | None) -> None:
    """SLR: a Prolog-like language over robot event streams, in one SQLite file.

    DB is the store's file; load, add, ingest, run, demo and serve create it, the other
    commands need an existing store. DB may also be the URL of a running `slr serve`
    (http://HOST:PORT) or of a PostgreSQL store (postgresql://USER@HOST/DB, docs/postgres.md).
    """
    ctx.obj = {"token": token}
    warnings.showwarning = _show_warning


def _show_warning(message: Warning | str, category: type[Warning], filename: str,
                  lineno: int, file: Any = None, line: str | None = None) -> None:
    """The library's warnings (a learned delay capped, ...) as ``warning: ...`` lines."""
    _err(f"warning: {message}")


# ---------------------------------------------------------------------------------------------
# demo
# ---------------------------------------------------------------------------------------------

@main.command()
@click.option("--db", "db_path", type=click.Path(dir_okay=False), default=None,
              help="Keep the scenario in this new file (default: a temporary in-memory store).")
def demo(db_path: str | None) -> None:
    """Play the robot scenario of the SLR paper and print the answers."""
    from rich.console import Console

    from .demo import run_demo

    if db_path is not None:
        refuse_memory_store(db_path, "slr demo --db")
    if db_path is not None and os.path.exists(db_path) and os.path.getsize(db_path) > 0:
        raise click.UsageError(f"{db_path} exists; the demo wants a fresh store (remove it first)")
    run_demo(Console(highlight=False), db_path=db_path)


# ---------------------------------------------------------------------------------------------
# load / add / ingest
# ---------------------------------------------------------------------------------------------

@main.command()
@click.argument("db", type=click.Path(dir_okay=False))
@click.argument("file", type=click.Path(dir_okay=False))
@click.option("--name", default="main", show_default=True,
              help="the program to add FILE's clauses to")
@click.option("--replace", is_flag=True,
              help="make the program NAME exactly FILE (rerunnable: no second copy)")
def load(db: str, file: str, name: str, replace: bool) -> None:
    """Add the clauses and declarations of FILE to the program NAME in DB."""
    _existing_file(file)
    with _open(db) as kb:
        kb.load_file(file, name=name, replace=replace)
    click.echo(f"{'replaced' if replace else 'loaded'} {printable_name(file)} as program "
               f"{printable_name(name)}")
    _warn_event_like_facts(file, db)


def _warn_event_like_facts(file: str, db: str) -> None:
    """Facts written like events (``obj(cup1, cup, red)^2.0.``) in a loaded program are
    rules' facts, which prev/next never see: say so, and how to add them as events."""
    from .example_files import event_like_facts, parse_example

    try:
        with open(file, encoding="utf-8") as handle:
            text = handle.read()
        facts = event_like_facts(text, file)
    except (OSError, UnicodeDecodeError, slr_sql.SLRError):
        return
    if not facts:
        return
    line, first = facts[0]
    more = f" (and {len(facts) - 1} more)" if len(facts) > 1 else ""
    _err(f"warning: {file}:{line}: {first} is a fact{more}, not an event: prev and next see "
         f"only events")
    if parse_example(text, file).has_events_part:
        _err(f"  to load its rules and add the events after '%% events' into a new store: "
             f"slr run {file} --db NEW.db")
    else:
        _err(f"  to add such lines as events: slr add {shown_location(db)} 'EVENT' ..., or one per line "
             f"with slr ingest {shown_location(db)} FILE")


@main.command()
@click.argument("db", type=click.Path(dir_okay=False))
@click.argument("events", nargs=-1, required=True)
def add(db: str, events: tuple[str, ...]) -> None:
    """Add EVENTS, each in SLR syntax: 'obj(cup1, cup, red)^2.0' or 'seen(x)^[1,2]'.

    Each event is stored or rejected on its own; if any is rejected, the output says which
    were stored and which were not, and the exit status is 1.
    """
    stored: list[int] = []
    rejected: list[int] = []
    with _open(db) as kb:
        for number, event in enumerate(events, start=1):
            try:
                kb.add(strip_full_stop(event))
            except slr_sql.SLRSyntaxError as exc:
                rejected.append(number)
                _err(f"error: event {number} rejected:\n{printable_syntax_error(exc)}")
            except slr_sql.SLRError as exc:
                rejected.append(number)
                _err(f"error: event {number} rejected: {error_words(exc)}")
            else:
                stored.append(number)
    if not rejected:
        click.echo(f"added {len(events)} event{'s' if len(events) != 1 else ''}")
        return
    listed = ", ".join(map(str, stored))
    click.echo(f"stored {len(stored)} of {len(events)} events" + (f" ({listed})" if stored else "")
               + f"; rejected {len(rejected)} ({', '.join(map(str, rejected))})")
    sys.exit(1)


class BadLine(ValueError):
    """A line of an ingest file that is not an event."""


def _json_args(args: list) -> list:
    """JSON event arguments as terms, in the store's own JSON encoding (docs/schema.md):
    a JSON string is an atom, ``{"$string":"text"}`` a string, ``{"f":[..]}`` the compound
    ``f(..)``, an array a list.  So what ``slr sql`` shows can be ingested back."""
    try:
        items, _ = list_items(decode(json.dumps(args)))
    except RecursionError:
        raise BadLine("bad argument: nested too deeply") from None
    except (ValueError, TypeError) as exc:
        # (Python's advice for an integer of more than 4,300 digits names
        # sys.set_int_max_str_digits: said in the user's words, as kb.add says it)
        from .plans import python_words
        raise BadLine(f"bad argument: {python_words(exc)}") from None
    return items


def _json_time(obj: dict, key: str) -> float:
    value = obj.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise BadLine(f'"{key}" must be a number')
    try:
        return float(value)
    except OverflowError:
        raise BadLine(f'"{key}" must be a finite number') from None


def _json_object(text: str) -> Any:
    """``json.loads`` with every failure a :class:`BadLine` in words."""
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise BadLine(f"invalid JSON: {exc.msg} at column {exc.colno}") from None
    except RecursionError:
        raise BadLine("invalid JSON: nested too deeply") from None
    except ValueError as exc:  # an integer of more digits than Python converts
        found = re.search(r"value has (\d+) digits", str(exc))
        raise BadLine(f"invalid JSON: an integer too large to read ("
                      f"{found.group(1) + ' digits' if found else exc}; at most "
                      f"{sys.get_int_max_str_digits()})") from None


def parse_event_line(line: str) -> str | tuple | None:
    """One ingest line as something ``kb.add_many`` takes, or None for blank/comment lines.

    A line starting with ``{`` is a JSON object ``{"name", "args", "start", "end"}`` (or
    ``"time"`` for a point event; arguments in the store's JSON encoding); anything else is SLR event text such as
    ``seg(cup1,[0.4,0.1,0.9])^12.31`` (a final full stop is allowed).
    Raises :class:`BadLine` for JSON that is not an event; SLR text is checked by the store.

    >>> parse_event_line("bump(r1)^12.31.")
    ('bump', (Atom('r1'),), 12.31, 12.31)
    >>> parse_event_line('{"name": "speed", "args": ["r1", 0.5], "time": 3}')
    ('speed', [Atom('r1'), 0.5], 3.0, 3.0)
    >>> parse_event_line("% a comment") is None
    True
    """
    text = line.strip()
    if not text or text.startswith("%") or text.startswith("#"):
        return None
    if not text.startswith("{"):
        text = strip_full_stop(text)
        try:
            return parse_event_fast(text) or text
        except (ValueError, RecursionError):  # the full parser (in add_many) says why
            return text
    obj = _json_object(text)
    if not isinstance(obj, dict):
        raise BadLine("a JSON line must be an object")
    name = obj.get("name")
    if not isinstance(name, str) or not name:
        raise BadLine('"name" must be a non-empty string')
    args = obj.get("args", [])
    if not isinstance(args, list):
        raise BadLine('"args" must be a list')
    if "time" in obj and "start" not in obj and "end" not in obj:
        start = end = _json_time(obj, "time")
    else:
        start = _json_time(obj, "start")
        end = _json_time(obj, "end") if "end" in obj else start
    return (name, _json_args(args), start, end)


@dataclass
class IngestReport:
    added: int
    bad: list[tuple[int, str]]  # (line number, reason)
    # reading stopped after this many lines, for this reason (an I/O error of the disk, a
    # network file system); the lines before it were ingested. None: read to its end.
    unread: tuple[int, str] | None = None


_EMBEDDED_POSITION = re.compile(r"<[a-z]+>:\d+:(\d+): (.*)")


def _reason(exc: Exception) -> str:
    """A one-line reason for an ``ingest`` report (the line number is printed separately)."""
    if isinstance(exc, slr_sql.SLRSyntaxError):
        return f"{exc.message} (column {exc.column})" if exc.column else exc.message
    first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    # A rejection that wraps a syntax error repeats the event text and says where in it
    # the error is; the event text is already the reported line, so keep message + column.
    embedded = _EMBEDDED_POSITION.search(first)
    if embedded:
        return f"{embedded.group(2)} (column {embedded.group(1)})"
    return first


def _add_batch(kb: KnowledgeBaseAPI, batch: list[tuple[int, Any]], bad: list[tuple[int, str]]) -> int:
    """Add a batch in one ``kb.add_many`` transaction; returns how many events were stored.

    ``add_many`` stores the good events of a batch and returns the rejected ones (each with
    ``.index`` into the batch), which are reported against their lines.  If it raises
    instead (nothing stored), the batch goes in event by event so a bad line costs only itself.
    """
    if not batch:
        return 0
    try:
        rejected = kb.add_many([event for _, event in batch])
    except slr_sql.SLRError:
        rejected = None
    if rejected is not None:
        rejections = [r for r in (rejected if isinstance(rejected, list) else []) if isinstance(r, Exception)]
        for rejection in rejections:
            index = getattr(rejection, "index", None)
            lineno = batch[index][0] if isinstance(index, int) and 0 <= index < len(batch) else 0
            bad.append((lineno, _reason(rejection)))
        return len(batch) - len(rejections)
    added = 0
    for lineno, event in batch:
        try:
            if isinstance(event, str):
                kb.add(event)
            else:
                name, args, start, end = event
                kb.add_event(name, args, start=start, end=end)
            added += 1
        except slr_sql.SLRError as exc:
            bad.append((lineno, _reason(exc)))
    return added


class _Unreadable(Exception):
    """Reading the input failed (an I/O error) after ``lines`` lines."""

    def __init__(self, lines: int, reason: str):
        super().__init__(reason)
        self.lines, self.reason = lines, reason


def _numbered_lines(handle: Iterable[bytes]) -> Iterator[tuple[int, bytes]]:
    lineno = 0
    lines = iter(handle)
    while True:
        try:
            line = next(lines)
        except StopIteration:
            return
        except OSError as exc:
            raise _Unreadable(lineno, exc.strerror or str(exc)) from None
        lineno += 1
        yield lineno, line


def ingest_file(kb: KnowledgeBaseAPI, path: str | Any, progress: Any = None) -> IngestReport:
    r"""Ingest every event line of ``path`` (a file name, or a binary stream such as
    ``sys.stdin.buffer``) into ``kb`` in batches; bad lines are collected, the rest still goes
    in. ``progress(nbytes)`` is called with the size of each line read.

    >>> import pathlib, tempfile
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "events.txt"
    >>> _ = path.write_text('pos(r1, 1)^1\n{"name": "pos", "args": ["r1", 2], "time": 2}\npos(r1\n')
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> report = ingest_file(kb, str(path)); report.added, report.bad
    (2, [(3, "unexpected end of text (unbalanced parenthesis: missing ')' for the '(' at line 1, column 4) (column 7)")])
    >>> kb.query("pos(r1, X)^T")
    [{'X': 1, 'T': 1.0}, {'X': 2, 'T': 2.0}]
    """
    bad: list[tuple[int, str]] = []
    added = 0
    batch: list[tuple[int, Any]] = []
    unread: tuple[int, str] | None = None
    handle = open(path, "rb") if isinstance(path, (str, os.PathLike)) else path
    try:  # decoded line by line: one bad byte costs one line
        for lineno, raw in _numbered_lines(handle):
            if progress is not None:
                progress(len(raw))
            try:
                try:
                    line = raw.decode("utf-8")
                except UnicodeDecodeError as exc:
                    raise BadLine(f"not UTF-8 text (byte 0x{raw[exc.start]:02x} at column "
                                  f"{exc.start + 1})") from None
                event = parse_event_line(line)
            except BadLine as exc:
                bad.append((lineno, str(exc)))
                continue
            if event is None:
                continue
            batch.append((lineno, event))
            if len(batch) >= INGEST_BATCH:
                added += _add_batch(kb, batch, bad)
                batch = []
    except _Unreadable as exc:   # the lines read go in all the same (what was read is good)
        unread = (exc.lines, exc.reason)
    finally:
        if handle is not path:
            handle.close()
    added += _add_batch(kb, batch, bad)
    bad.sort()
    return IngestReport(added, bad, unread)


class LineProgress:
    """Progress of an ingest into a log (stderr not a terminal, ``--progress``): one line
    per tenth of a file, or per 64 MiB of a stream whose size is unknown."""

    def __init__(self, label: str, total: int | None):
        self.label, self.total, self.done, self.next_mark = label, total, 0, 0

    def __call__(self, nbytes: int) -> None:
        self.done += nbytes
        if self.done < self.next_mark:
            return
        if self.total:
            percent = min(100, 100 * self.done // self.total)
            _err(f"{self.label}: {percent}% ({self.done:,} of {self.total:,} bytes)")
            self.next_mark = (percent // 10 + 1) * self.total // 10
        else:
            _err(f"{self.label}: {self.done:,} bytes")
            self.next_mark = self.done + 64 * 1024 * 1024


@main.command()
@click.argument("db", type=click.Path(dir_okay=False))
@click.argument("file", type=click.Path(dir_okay=False, allow_dash=True))
@click.option("--progress/--no-progress", default=None,
              help="Report progress on stderr (default: a bar on a terminal for long input).")
def ingest(db: str, file: str, progress: bool | None) -> None:
    """Add the events of FILE (- for standard input): one per line, SLR text or JSON.

    \b
      seg(cup1,[0.4,0.1,0.9])^12.31
      {"name":"seg","args":["cup1",[0.4,0.1,0.9]],"start":12.31,"end":12.31}

    Bad lines are reported as FILE:LINE: reason and skipped; the exit status is 1 if any.
    """
    if file == "-":
        source: Any = sys.stdin.buffer
        label, size = "<stdin>", None
    else:
        source = _existing_file(file)
        label, size = file, os.path.getsize(file)
    terminal = sys.stderr.isatty()
    if progress is None:   # a bar only where a person watches, and only when it is long
        progress = terminal and (size is None or size >= PROGRESS_MIN_BYTES)
    with _open(db) as kb:
        if progress and terminal:
            from rich.console import Console
            from rich.markup import escape
            from rich.progress import BarColumn, DownloadColumn, Progress, TimeRemainingColumn

            columns = ("[progress.description]{task.description}", BarColumn(),
                       DownloadColumn(), TimeRemainingColumn())
            with Progress(*columns, console=Console(stderr=True), transient=True) as bar:
                # (the description is rich markup: a file's name is text, never markup)
                task = bar.add_task(
                    f"ingesting {escape(printable_name(os.path.basename(label)))}", total=size)
                report = ingest_file(kb, source, lambda n: bar.update(task, advance=n))
        elif progress:
            report = ingest_file(kb, source, LineProgress(f"ingesting {label}", size))
        else:
            report = ingest_file(kb, source)
    for lineno, reason in report.bad:
        _err(f"{label}:{lineno}: {reason}")
    click.echo(f"ingested {report.added} event{'s' if report.added != 1 else ''}"
               + (f", {len(report.bad)} bad line{'s' if len(report.bad) != 1 else ''}" if report.bad else ""))
    if report.unread is not None:
        lines, reason = report.unread
        _err(f"error: cannot read {label} after line {lines}: {reason} (the events of the "
             f"lines before it were ingested)")
    if report.bad or report.unread is not None:
        sys.exit(1)


# ---------------------------------------------------------------------------------------------
# run: an example file (program, events, queries with expected answers)
# ---------------------------------------------------------------------------------------------

@main.command()
@click.argument("file", type=click.Path(dir_okay=False))
@click.option("--db", "db", type=click.Path(dir_okay=False), default=None,
              help="Keep the store in this file (default: in memory).")
@click.option("-q", "--quiet", is_flag=True, help="Print only the mismatches and the summary.")
def run(file: str, db: str | None, quiet: bool) -> None:
    """Run an example FILE: load its rules, add its events, ask its queries, compare.

    The rules are the text before '%% events', the events the lines after it; each
    '%% query:' is asked and its answers compared with '%% expect:' (examples/README.md).
    Exit status 1 when an answer differs.
    """
    from .example_files import check_case, parse_example

    _existing_file(file)
    try:
        with open(file, encoding="utf-8") as handle:
            text = handle.read()
    except UnicodeDecodeError:
        raise slr_sql.SLRError(f"{file}: not an example file (not UTF-8 text)") from None
    except OSError as exc:   # an I/O error of the disk, a name too long, ...
        raise slr_sql.SLRError(f"cannot read {file}: {exc.strerror or exc}") from None
    example = parse_example(text, file)
    if db is not None and os.path.exists(db) and os.path.getsize(db) > 0:
        raise slr_sql.SLRError(f"{shown_location(db)} exists; slr run wants a fresh store (remove it first)")
    if db is not None:
        refuse_memory_store(db, "slr run --db")
    # The events are a recording: time stands still at 0, so no buffer prunes them and
    # every query sees the file's events however long ago their times are.
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.load(example.program, file)
        rejected = kb.add_many(example.events) if example.events else []
        for rejection in rejected:
            index = getattr(rejection, "index", None)
            where = (example.event_lines[index] if isinstance(index, int)
                     and 0 <= index < len(example.event_lines) else 0)
            _err(f"{file}:{where}: event rejected: {error_words(rejection)}")
        if not quiet:
            click.echo(printable_text(
                f"% {file}: {len(example.events) - len(rejected)} events, "
                f"{len(example.cases)} quer{'y' if len(example.cases) == 1 else 'ies'}"))
        failed = 0
        for case in example.cases:
            view = "" if case.at is None else f"  (at {case.at:g})"
            try:
                result = check_case(kb, case)
            except slr_sql.SLRError as exc:
                failed += 1
                click.echo(printable_text(f"ERROR {file}:{case.line}: ?- {case.goal}.{view}\n"
                                          f"      {error_words(exc)}"))
                continue
            lines = answer_lines(result.answers)
            if result.ok is False:
                failed += 1
                click.echo(printable_text(f"FAIL  {file}:{case.line}: ?- {case.goal}.{view}"))
                click.echo(printable_text(f"      expected {case.expect}"))
                for line in lines:
                    click.echo(f"      got      {line}")
            elif not quiet:
                mark = "ok   " if result.ok else "     "
                click.echo(printable_text(f"{mark} ?- {case.goal}.{view}"))
                for line in lines:
                    click.echo(f"        {line}")
    compared = sum(1 for c in example.cases if c.expect is not None)
    click.echo(f"{compared - failed} of {compared} expected answers matched"
               + (f"; {len(rejected)} events rejected" if rejected else ""))
    if failed or rejected:
        sys.exit(1)


# ---------------------------------------------------------------------------------------------
# query / explain
# ---------------------------------------------------------------------------------------------

def answer_lines(answers: list[dict[str, Any]]) -> list[str]:
    """One line per answer, ``X = a, Y = [1,2]``; ``true.`` for an answer without
    variables and ``false.`` when there is no answer, as the Prolog top level says.

    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0)); kb.add_many(["pos(r1, 1)^1", "pos(r1, [a,b])^2"])
    []
    >>> answer_lines(kb.query("pos(R, X)^T"))
    ['R = r1, X = 1, T = 1.0', 'R = r1, X = [a,b], T = 2.0']
    >>> answer_lines(kb.query("true")), answer_lines(kb.query("pos(r2, X)^T"))
    (['true.'], ['false.'])
    """
    if not answers:
        return ["false."]
    return [answer_text(a) if a else "true." for a in answers]


def _print_answers(answers: list[dict[str, Any]]) -> None:
    for line in answer_lines(answers):
        click.echo(line)


class AnswerPrinter:
    """Prints answers as they come: Prolog's top-level lines, or one JSON object per
    answer (the service's encoding, docs/service.md) for ``--json``; ``false.`` (text only)
    when there was none."""

    def __init__(self, as_json: bool):
        self.as_json = as_json
        self.count = 0

    def __call__(self, answer: dict[str, Any]) -> None:
        self.count += 1
        if self.as_json:
            from .service.encoding import dumps, encode_answers

            line = dumps(encode_answers([answer])[0]).decode("utf-8")
        else:
            line = answer_text(answer) if answer else "true."
        click.echo(line)

    def finish(self) -> None:
        if not self.count and not self.as_json:
            click.echo("false.")


def _warn_about(kb: KnowledgeBaseAPI, goal: str) -> None:
    """The library's warnings about a goal (a predicate nobody defined: a typo?) on stderr."""
    if not hasattr(kb, "goal_warnings"):
        return
    try:
        warnings = kb.goal_warnings(goal)
    except slr_sql.SLRError:   # the query itself reports a bad goal, once
        return
    for warning in warnings:
        _err(f"warning: {warning}")


@main.command()
@click.argument("db", type=click.Path(dir_okay=False))
@click.argument("goal")
@click.option("--at", "at", type=float, default=None,
              help="The stream view: only events with end time <= Z (outside prev/next).")
@click.option("--wait", is_flag=True,
              help="Synchronized: answer once the events the goal depends on are complete up to "
                   "--at (default: now).")
@click.option("--timeout", type=float, default=None,
              help="Give up after S seconds (the answers found so far are printed first).")
@click.option("--limit", type=click.IntRange(min=0), default=None, metavar="N",
              help="Stop after N answers.")
@click.option("--json", "as_json", is_flag=True,
              help="One JSON object per answer (the service's encoding); no answer: no line.")
@click.option("--robot", default=None,
              help="Only this robot's events (every event goal, prev and next).")
def query(db: str, goal: str, at: float | None, wait: bool, timeout: float | None,
          limit: int | None, as_json: bool, robot: str | None) -> None:
    """Ask GOAL and print one answer per line (`false.` when there is none)."""
    goal = strip_full_stop(goal)
    # --at is the library's at= (and the shell's `at`): inf (every stored event) and -inf
    # (none) are views, NaN is none
    check_time_option("--at", at)
    # --timeout is the library's timeout= : inf (or 1e400) is no limit, NaN and < 0 are none
    check_time_option("--timeout", timeout, minimum=0.0)
    printer = AnswerPrinter(as_json)
    with _open(db, create=False) as kb:
        _warn_about(kb, goal)
        if wait:
            if not hasattr(kb, "submit"):
                _err("error: synchronized queries are not available in this build")
                sys.exit(2)
            import concurrent.futures

            # Without --at the library synchronizes on "now" (the store clock); other
            # processes may add the events and marks it waits for.
            if hasattr(kb, "synchronizer"):
                kb.synchronizer.watch_external()
            pending = kb.submit(goal, at=at, id=f"slr-query-{os.getpid()}", timeout=timeout,
                                **({"robot": robot} if robot is not None else {}))
            try:
                answers = pending.result(timeout=None if timeout is None else timeout + 5.0)
            except concurrent.futures.TimeoutError:
                message = (pending.timeout_message(timeout) if hasattr(pending, "timeout_message")
                           else f"the query was not answerable within {timeout:g} s")
                _err(f"error: {message}")
                sys.exit(1)
            if hasattr(pending, "explain"):  # what it waited for and how long, as comments
                for line in pending.explain().splitlines():
                    _err(f"% {line}")
            for answer in answers[:limit]:
                printer(answer)
        elif limit is None and not isinstance(kb, KnowledgeBase):
            # (served, every answer wanted: one POST /query. Over /solutions each answer is
            # a round trip of its own, which the server's query time counts: a goal of tens
            # of thousands of answers that one request gives in a second ran out of it)
            try:
                for answer in kb.query(goal, at=at, timeout=timeout,
                                       **({"robot": robot} if robot is not None else {})):
                    printer(answer)
            except slr_sql.SLRTimeout as exc:
                _err(f"error: {error_words(exc)}")
                sys.exit(1)
        elif limit != 0:
            # (answers one at a time, local or served: the search, here or on the server,
            # ends at the limit's last answer instead of running on)
            solutions = kb.solutions(goal, at=at, timeout=timeout,
                                     **({"robot": robot} if robot is not None else {}))
            try:
                for answer in solutions:
                    printer(answer)
                    if printer.count == limit:
                        break
            except slr_sql.SLRTimeout as exc:
                _err(f"error: {error_words(exc)}"
                     + (f" ({printer.count} answer{'s' if printer.count != 1 else ''} "
                        f"printed before it)" if printer.count else ""))
                sys.exit(1)
            finally:
                solutions.close()
    printer.finish()


@main.command()
@click.argument("db", type=click.Path(dir_okay=False))
@click.argument("goal")
def explain(db: str, goal: str) -> None:
    """Show how GOAL would run: compiled to SQL or interpreted, and why."""
    with _open(db, create=False) as kb:
        click.echo(printable_text(kb.explain(strip_full_stop(goal))))


# ---------------------------------------------------------------------------------------------
# programs / unload / describe: what is in a store
# ---------------------------------------------------------------------------------------------

EPOCH_2001 = 978_307_200.0   # times past this are read as Unix time (a robot's clock)


def time_text(t: float | None) -> str:
    """A time as the command line prints it: the number, and for an epoch-second time
    (after 2001) also the UTC date and time.

    >>> time_text(12.5), time_text(1700000000.25)
    ('12.5', '1700000000.25 (2023-11-14 22:13:20.250 UTC)')
    """
    if t is None:
        return "-"
    if not math.isfinite(t) or t < EPOCH_2001:
        return f"{t:g}" if abs(t) < 1e15 else repr(t)
    import datetime

    moment = datetime.datetime.fromtimestamp(t, tz=datetime.UTC)
    return f"{t:.2f} ({moment.strftime('%Y-%m-%d %H:%M:%S.%f')[:-3]} UTC)"


def _program_infos(kb: KnowledgeBaseAPI) -> list[Any]:
    infos = kb.programs()
    return list(infos.values()) if isinstance(infos, dict) else list(infos)


def _info_field(info: Any, name: str) -> Any:
    return info.get(name) if isinstance(info, dict) else getattr(info, name, None)


@main.command()
@click.argument("db", type=click.Path(dir_okay=False))
@click.option("--source", is_flag=True, help="Print each program's text too.")
def programs(db: str, source: bool) -> None:
    """List the named programs in DB: name, texts loaded, files, when."""
    with _open(db, create=False) as kb:
        infos = _program_infos(kb)
    if not infos:
        click.echo("no programs")
    for info in infos:
        files = ", ".join(map(printable_name, dict.fromkeys(_info_field(info, "filenames") or ())))
        texts = _info_field(info, "texts") or 0
        click.echo(f"{printable_name(_info_field(info, 'name'))}: {texts} text{'s' if texts != 1 else ''}"
                   f" from {files or '<string>'}, loaded {time_text(_info_field(info, 'loaded_at'))}")
        if source:
            for line in (_info_field(info, "source") or "").splitlines():
                click.echo(f"    {printable_text(line)}")


@main.command()
@click.argument("db", type=click.Path(dir_okay=False))
@click.argument("name")
def unload(db: str, name: str) -> None:
    """Remove the program NAME (its clauses, declarations and buffers; events stay)."""
    with _open(db, create=False) as kb:
        kb.unload(name)
    click.echo(f"unloaded program {printable_name(name)}")


@dataclass
class TypeSummary:
    """One event type of a store, as ``slr describe`` shows it."""

    name: str
    arity: int
    table: str
    count: int
    first: float | None          # the earliest end time
    last: float | None           # the latest end time
    sample: str | None           # the first event in store order, as SLR text
    rules: list[str]             # predicates (rules) that read or define it
    buffers: list[str]           # buffers whose pattern is of this type
    event_rules: list[str]       # event rules that match it or derive it


def describe_types(kb: KnowledgeBase, wanted: Iterable[str] = ()) -> list[TypeSummary]:
    """What ``slr describe`` prints: a :class:`TypeSummary` per event type of ``kb`` (or of
    ``wanted``: ``seg`` or ``seg/2``), in name order.

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.load("color(O,C)^T :- prev(obj(O,_,C)^Z, T).")
    >>> kb.add_many(["obj(cup1, cup, red)^2", "obj(cup1, cup, blue)^5"])
    []
    >>> s = describe_types(kb)[0]; (s.name, s.arity, s.count, s.first, s.last, s.rules)
    ('obj', 3, 2, 2.0, 5.0, ['color/2^'])
    """
    from .analysis import analyze
    from .parser import parse_term
    from .program import event_key, split_event_atom
    from .terms import format_atom, format_term

    store = kb.store
    types = dict(store.event_types())
    for key in store.declared_types():
        types.setdefault(key, store.table_for(*key) or "-")
    chosen = []
    for spec in wanted:
        # NAME/ARITY splits at the last slash, and only before digits: a type whose name
        # holds a slash ('a/b') is chosen by a/b/1, or by its whole name a/b; or by the
        # name quoted as Prolog writes it ('a/b'/1, read as Prolog reads it)
        name, arity = parse_indicator(spec)
        found = [k for k in types if k[0] == name and arity in (None, k[1])]
        if not found and arity is not None and not spec.startswith("'"):
            found = [k for k in types if k[0] == spec]
        if not found:
            raise slr_sql.SLRError(f"no event type {spec} in the store (known: "
                                   f"{', '.join(sorted(f'{n}/{a}' for n, a in types)) or 'none'})")
        chosen += found
    keys = sorted(set(chosen) if chosen else types)
    analysis = analyze(kb.engine.program)
    readers: dict[tuple[str, int], list[str]] = {}
    for node, stored in analysis.stored.items():
        for key in stored:
            if node.kind == "event" and (node.name, node.arity) == key:
                continue
            mark = "^" if node.kind == "event" else ""   # color/2^: the rules of color(..)^T
            readers.setdefault(key, []).append(f"{format_atom(node.name)}/{node.arity}{mark}")
    buffers: dict[tuple[str, int], list[str]] = {}
    for info in kb.buffers():
        try:
            pattern = parse_term(info.pattern, "<buffer>")[0]
            split = split_event_atom(pattern)
            key = event_key(split[0] if split else pattern)
        except (slr_sql.SLRError, TypeError, ValueError, AttributeError):
            continue
        buffers.setdefault(key, []).append(f"{info.kind}({info.pattern}, {info.amount:g})")
    event_rules = kb.event_rules() if hasattr(kb, "event_rules") else []
    out = []
    for name, arity in keys:
        rules = sorted(set(readers.get((name, arity), [])))
        if (name, arity) in kb.engine.program.temporal:
            rules.insert(0, f"{format_atom(name)}/{arity}^ (defines it)")
        rows = iter(store.scan(name, arity)) if store.table_for(name, arity) else iter(())
        first_row = next(rows, None)
        sample = None
        if first_row is not None:
            args, start, end = first_row[0], first_row[1], first_row[2]
            atom = format_term(slr_sql.Struct(name, tuple(args))) if args else format_atom(name)
            sample = f"{atom}^{end!r}" if start == end else f"{atom}^[{start!r},{end!r}]"
        derived = [r["rule"] for r in event_rules if r.get("head") == f"{name}/{arity}"]
        matching = [r["rule"] for r in event_rules
                    if re.search(rf"(?<![\w']){re.escape(name)}\(", str(r.get("pattern", "")))]
        out.append(TypeSummary(
            name, arity, types.get((name, arity)) or "-", store.count(name, arity)
            if store.table_for(name, arity) else 0,
            first_row[2] if first_row is not None else None,
            store.max_end(name, arity) if first_row is not None else None,
            sample, rules, buffers.get((name, arity), []),
            list(dict.fromkeys(derived + matching))))
    return out


@main.command()
@click.argument("db", type=click.Path(dir_okay=False))
@click.argument("types", nargs=-1, metavar="[TYPE]...")
@click.option("--all", "show_all", is_flag=True,
              help="Include the store's internal types (slr_import/3, ...).")
def describe(db: str, types: tuple[str, ...], show_all: bool) -> None:
    """Each event type: arity, count, first/last time, a sample, the rules and buffers on it."""
    if _is_url(db):
        raise slr_sql.SLRError("describe needs the store itself, not a service URL")
    with _open(db, create=False) as kb:
        summaries = describe_types(kb, types)
    if not types and not show_all:
        summaries = [s for s in summaries if not s.name.startswith("slr_")]
    if not summaries:
        click.echo("no event types")
    for s in summaries:
        click.echo(f"{printable_name(s.name)}/{s.arity}  (table {s.table})")
        click.echo(f"  events:      {s.count}")
        if s.count:
            click.echo(f"  end times:   {time_text(s.first)} .. {time_text(s.last)}")
        if s.sample:
            click.echo(f"  sample:      {s.sample}")
        for label, items in (("rules:", s.rules), ("buffers:", s.buffers),
                             ("event rules:", s.event_rules)):
            if items:
                click.echo(f"  {label:<12} {printable_text(items[0])}")
                for item in items[1:]:
                    click.echo(f"  {'':<12} {printable_text(item)}")


# ---------------------------------------------------------------------------------------------
# sql
# ---------------------------------------------------------------------------------------------

def run_sql(db: str, statement: str, write: bool = False) -> tuple[list[str], list[tuple]]:
    """Run one SQL statement against the store; returns (column names, rows).

    Through ``kb.sql``, so the store's ``slr_`` SQL functions (which the statements printed by
    ``slr explain`` call) are there; read-only unless ``write``, so a mistyped UPDATE or DROP
    cannot damage the store.

    >>> import pathlib, tempfile
    >>> db = str(pathlib.Path(tempfile.mkdtemp()) / "robot.db")
    >>> kb = slr_sql.open(db, clock=slr_sql.ManualClock(0)); kb.add("pos(r1, 1)^1"); kb.close()
    >>> run_sql(db, "SELECT arg1, arg2, t_end FROM pos")
    (['arg1', 'arg2', 't_end'], [('r1', 1, 1.0)])
    >>> run_sql(db, "DELETE FROM pos")
    Traceback (most recent call last):
        ...
    slr_sql.errors.SLRError: read-only: the statement would change the store (attempt to write a readonly database); `slr sql --write` allows it
    """
    with _open(db, create=False) as kb:
        if _is_url(db):
            if write:
                raise slr_sql.SLRError("sql over the service is read-only: --write needs "
                                       "the store's file")
            columns, rows = kb.sql(statement)
            return list(columns), [tuple(r) for r in rows]
        try:
            columns, rows = kb.sql(statement, write=write)
        except slr_sql.SLRError as exc:
            message = str(exc)
            if message.startswith("read-only"):
                # The library's message speaks to Python callers (write=True); say it the
                # command line's way, once.
                message = re.sub(r"[;,]? *(pass|use|with) `?write=True`?[^;()]*", "", message)
                raise slr_sql.SLRError(f"{message.rstrip('. ')}; `slr sql --write` allows it") \
                    from None
            raise
        return list(columns), [tuple(r) for r in rows]


SQL_FORMATS = ("table", "csv", "tsv", "json", "nl")


def json_cell(value: Any) -> Any:
    """``value`` (a cell of ``kb.sql``) as ``--json`` and ``--nl`` write it: the service's
    encoding of SQL rows (:func:`~slr_sql.service.encoding.encode_plain`, what ``POST /sql``
    answers and a client of the service decodes back). SQLite's cells are numbers, text,
    blobs and NULL; PostgreSQL's come as psycopg reads its types. A blob is
    ``{"$bytes": hex}``, a non-finite float ``{"$float": "inf" | "-inf" | "nan"}`` (also
    inside an array), a NUMERIC (``sum`` or ``avg`` of an integer column) the number it is
    (an integer when it has no fractional digits, as SQLite's ``sum`` gives one), a boolean,
    an array and a json value the JSON they are, and a timestamp, date, interval, uuid,
    range or address its text.

    >>> from decimal import Decimal; import datetime
    >>> json_cell(Decimal("190")), json_cell(Decimal("10.50")), json_cell([Decimal("1")])
    (190, 10.5, [1])
    >>> json_cell(datetime.date(2026, 11, 29)), json_cell(b"\\x00\\xff"), json_cell({"a": 1})
    ('2026-11-29', {'$bytes': '00ff'}, {'a': 1})
    >>> json_cell([float("inf"), None])
    [{'$float': 'inf'}, None]
    """
    from .service.encoding import encode_plain

    return encode_plain(value)


def text_cell(value: Any) -> str | None:
    """``value`` (a cell of ``kb.sql``) as ``--csv``, ``--tsv`` and the table write it:
    text a CSV reader takes, never Python's notation. A boolean is ``true`` or ``false``
    (PostgreSQL's text of it; SQLite has none: its 1 and 0 stay numbers), a blob ``\\x``
    and its bytes in hex (PostgreSQL's text of a bytea, the digits ``--json`` writes as
    ``{"$bytes": hex}``), an array or a json value its JSON as ``--json`` writes it, a float
    as Python writes it (``inf``, ``-inf``, ``nan``) and NULL None (an empty field).

    >>> text_cell(True), text_cell(b"\\x00\\xff"), text_cell({"a": [1, "x"]}), text_cell(2.5)
    ('true', '\\\\x00ff', '{"a": [1, "x"]}', '2.5')
    >>> text_cell([1.5, float("inf"), None]), text_cell(None)
    ('[1.5, {"$float": "inf"}, null]', None)
    """
    if value is None:
        return None
    if type(value) is bool:
        return "true" if value else "false"
    if isinstance(value, (bytes, bytearray, memoryview)):
        return "\\x" + bytes(value).hex()
    if isinstance(value, (list, tuple, dict)):
        # (", " and ": " between items, as PostgreSQL writes a jsonb value)
        return json.dumps(json_cell(value), ensure_ascii=False)
    return str(value)


def write_rows(columns: list[str], rows: Iterable[tuple], fmt: str, out: Any = None) -> None:
    """Rows in one of :data:`SQL_FORMATS`, as ``sqlite-utils query`` writes them: ``json`` a
    JSON array of row objects (one row a line), ``nl`` one JSON object a line, ``csv`` and
    ``tsv`` with a header line, ``table`` a box table for reading.

    ``json`` and ``nl`` write each cell as :func:`json_cell` says: JSON has no infinity nor
    NaN, so such a float is written as the service's encoding does (``{"$float": "inf"}``,
    ``"-inf"``, ``"nan"``; what ``slr query --json`` and ``POST /sql`` write), never the
    ``Infinity`` a JSON reader refuses, and a blob is ``{"$bytes": hex}``. ``csv``, ``tsv``
    and the table write each cell's :func:`text_cell` (docs/printed_text.md).

    >>> write_rows(["n", "name"], [(1, "cup1"), (2, None)], "nl")
    {"n": 1, "name": "cup1"}
    {"n": 2, "name": null}
    >>> write_rows(["x"], [(float("-inf"),)], "json")
    [{"x": {"$float": "-inf"}}]
    >>> write_rows(["b", "ok"], [(b"\\x01", True)], "csv")
    b,ok
    \\x01,true
    """
    import csv

    out = out or sys.stdout
    if fmt in ("json", "nl"):
        from sqlite_utils.cli import output_rows  # sqlite-utils' own JSON writer

        cells = ([json_cell(v) for v in row] for row in rows)
        for line in output_rows(cells, columns, nl=fmt == "nl", arrays=False, json_cols=False):
            out.write(line + "\n")
    elif fmt in ("csv", "tsv"):
        writer = csv.writer(out, dialect="excel-tab" if fmt == "tsv" else "excel",
                            lineterminator="\n")
        writer.writerow(columns)
        writer.writerows([text_cell(v) for v in row] for row in rows)
    else:
        from rich.console import Console
        from rich.table import Table

        # (the box table is for reading: its cells escaped as names are; csv, tsv and json
        # keep the values exact, each format escaping what its own rules say)
        table = Table(*map(printable_text, columns), show_lines=False)
        for row in rows:
            table.add_row(*("NULL" if v is None else printable_text(text_cell(v)) for v in row))
        # Into a pipe the table is not cut to the terminal's width.
        Console(file=out, highlight=False, markup=False,
                width=None if out.isatty() else 500).print(table)


@main.command()
@click.argument("db", type=click.Path(dir_okay=False))
@click.argument("statement")
@click.option("--table", "fmt", flag_value="table",
              help="A box table (the default on a terminal).")
@click.option("--csv", "fmt", flag_value="csv", help="CSV with a header line.")
@click.option("--tsv", "fmt", flag_value="tsv",
              help="Tab-separated with a header line (the default into a pipe or file).")
@click.option("--json", "fmt", flag_value="json", help="A JSON array of row objects.")
@click.option("--nl", "fmt", flag_value="nl", help="One JSON object per row (JSON lines).")
@click.option("--write", is_flag=True, help="Allow the statement to change the store.")
def sql(db: str, statement: str, fmt: str | None, write: bool) -> None:
    """Run a SQL STATEMENT on the store, e.g. "SELECT * FROM seg" (read-only unless --write)."""
    columns, rows = run_sql(db, statement, write=write)
    write_rows(columns, rows, fmt or ("table" if sys.stdout.isatty() else "tsv"))


# ---------------------------------------------------------------------------------------------
# shell
# ---------------------------------------------------------------------------------------------

SHELL_HELP = """\
  GOAL.              ask a goal (may span lines; ends with a full stop). After an answer:
                     ; (or n, space) the next one, Enter (or .) stop, w the answer in full
  :- DIRECTIVE.      a directive (e.g. :- event seen/1.), kept in the program 'user'
  [user].            type clauses into the program 'user'; end_of_file. or Ctrl-D ends
  assert(CLAUSE).    add a clause to the program 'user' (assertz; asserta puts it first)
  retract(CLAUSE).   remove the first clause of 'user' that unifies with CLAUSE
  listing.           the program 'user'; listing(NAME) or listing(NAME/N): its clauses
                     in every program
  programs.          the named programs of the store
  load FILE          load a program file (into 'main')
  add EVENT          add one event, e.g. add obj(cup1, cup, red)^2.0
  at Z | at none     set / clear the stream view for the following goals
  explain GOAL.      show the plan of a goal
  help               this text;  Ctrl-C stops a goal;  Ctrl-D or `halt.` leaves"""

SHELL_PROGRAM = "user"      # where the shell's clauses go (SWI-Prolog's module user)
MAX_DEPTH = 10     # SWI-Prolog's answer_write_options: max_depth(10), unless `w` is pressed
_CUT = Atom("...")


def abbreviated(value: Any, depth: int = 1) -> Any:
    """``value`` cut as SWI-Prolog's top level cuts an answer (``max_depth(10)``): a term
    nested deeper than 10 prints as ``...``, a compound's arguments are one deeper than it,
    and the k-th element of a list k deeper than the first, so that a list shows fewer
    elements the deeper it is (``[1,2,3,4,5,6,7,8,9|...]`` at the top, 8 in ``f(L)``).
    ``depth``: how deep ``value`` itself is. Strings are printed whole, as swipl 9 prints
    them.

    >>> value_text(abbreviated(list(range(1, 20)))), value_text(abbreviated([[1, 2, 3]], 9))
    ('[1,2,3,4,5,6,7,8,9|...]', '[[...|...]]')
    """
    if depth > MAX_DEPTH:
        return _CUT
    if isinstance(value, list):
        return _abbreviated_list(value, [], depth)
    if isinstance(value, Struct):
        if str(value.name) == "." and len(value.args) == 2:
            return _abbreviated_list([value.args[0]], value.args[1], depth)
        # (the depth bounds the recursion: nothing below MAX_DEPTH is walked)
        return Struct(value.name, tuple(abbreviated(a, depth + 1) for a in value.args))
    return value


def _abbreviated_list(items: list, tail: Any, depth: int) -> Any:
    """The list ``items`` then ``tail`` (``[]``, a Python list of the rest, a list cell or
    any other term: a partial list) at ``depth``, cut as :func:`abbreviated` says: its k-th
    element (from 0) is at ``depth + 1 + k``, and what follows the last element shown is
    ``|...`` once it would be deeper than the limit."""
    shown: list = []
    k = 0
    while True:
        if k == len(items):
            # the elements given are taken: go on into the tail (only as far as is shown)
            if isinstance(tail, list):
                items, tail = items + tail[:MAX_DEPTH + 1], (
                    [] if len(tail) <= MAX_DEPTH + 1 else tail[MAX_DEPTH + 1:])
            elif isinstance(tail, Struct) and str(tail.name) == "." and len(tail.args) == 2:
                items, tail = items + [tail.args[0]], tail.args[1]
            if k == len(items):      # no element left: the end, or a partial list's tail
                if isinstance(tail, list):    # ([] : a proper list, printed whole)
                    return shown
                rest = abbreviated(tail, depth + 1 + k)
                break
        if k and depth + 1 + k > MAX_DEPTH:
            rest = _CUT
            break
        shown.append(abbreviated(items[k], depth + 1 + k))
        k += 1
    for item in reversed(shown):
        rest = Struct(".", (item, rest))
    return rest


class ShellState:
    """What the next input line is: a new goal or command, the rest of an unfinished goal
    or clause, or a clause typed after ``[user].``."""

    READY = "ready"
    CONTINUING = "continuing"
    CONSULTING = "consulting"


class Shell:
    """The interactive loop, independent of where lines come from (prompt or plain stdin).

    ``ask`` reads the response to an answer: the key a person presses (:func:`read_key`),
    or a line of piped input (:class:`PipedInput`). None: every answer is printed, one per
    line (a knowledge base without ``solutions``)."""

    def __init__(self, kb: KnowledgeBaseAPI, echo: Any = click.echo, echo_err: Any = _err,
                 ask: Any = None):
        self.kb = kb
        # everything the shell prints may quote the store's names, a file's lines: escaped
        self.echo = lambda text="", **how: echo(printable_text(text), **how)
        self.echo_err = lambda text="", **how: echo_err(printable_text(text), **how)
        self.ask = ask
        self.at: float | None = None
        self.pending: list[str] = []
        self.consulted: list[str] = []
        self.state = ShellState.READY
        self.running: Any = None      # the answers whose next one is looked for now
        self.signalled = False        # stop_goal stopped them (a Ctrl-C)
        self.terminating: int | None = None   # ... for SIGTERM or SIGHUP: the shell ends

    @property
    def continuing(self) -> bool:
        return self.state != ShellState.READY

    @property
    def prompt(self) -> str:
        return {ShellState.READY: "?- ", ShellState.CONTINUING: "   | ",
                ShellState.CONSULTING: "|: "}[self.state]

    def stop_goal(self, terminating: int | None = None) -> bool:
        """(In the shell's SIGINT handler, a goal running) Whether the search for the goal's
        next answer on a local store was stopped: then the handler raises nothing, and that
        ``next()`` raises KeyboardInterrupt as the stop ends it (:meth:`_one_at_a_time`) --
        the interpreter at its next check, a statement compiled to SQL at once. Raised by the
        handler, the KeyboardInterrupt does not always reach a statement SQLite runs (one
        raised in a function of several arguments the statement calls is cleared by sqlite3:
        the goal goes on in the interpreter, and Ctrl-C did nothing; the store keeps one
        raised in the progress handler or a function of one argument, docs/sql.md), and one
        raised inside psycopg's wait for the server could leave
        the connection with its statement unread ("another command is already in
        progress"). False (the handler raises) for a served goal's answers, which end with
        the KeyboardInterrupt itself, outside the search (the key after an answer), and for
        a second Ctrl-C. ``terminating``: SIGTERM or SIGHUP came (its number): the stopped
        search raises :class:`ShellTerminated` instead, even after a Ctrl-C.

        >>> shell = Shell(slr_sql.open(), ask=lambda: ";"); shell.stop_goal()   # none runs
        False
        """
        answers = self.running
        if not isinstance(answers, Solutions):
            return False
        if terminating is not None:
            self.terminating = terminating
        elif self.signalled:
            return False
        self.signalled = True
        answers.stop()
        return True

    def interrupt(self) -> None:
        """Ctrl-C at the prompt: drop the unfinished goal (a consult keeps what it has)."""
        self.pending = []
        if self.state == ShellState.CONTINUING:
            self.state = ShellState.READY

    def end_of_input(self) -> bool:
        """Ctrl-D: ends a consult (True: stay), else leaves the shell (False)."""
        if self.state == ShellState.CONSULTING:
            self._guarded(self._end_consult)
            return True
        return False

    def feed(self, line: str) -> bool:
        """Handle one input line; returns False when the user asked to leave."""
        stripped = line.strip()
        if self.state == ShellState.CONSULTING:
            end = full_stop_end(stripped)   # (a comment may follow the full stop)
            if stripped == "end_of_file" or (end is not None
                                             and stripped[:end] == "end_of_file."):
                return self._guarded(self._end_consult)
            self.consulted.append(line.rstrip("\n"))
            return True
        if self.state == ShellState.READY:
            if not stripped or stripped.startswith("%"):
                return True
            word, _, rest = stripped.partition(" ")
            if stripped in ("halt.", "halt", "quit", "exit"):
                return False
            if word == "help":
                self.echo(SHELL_HELP)
                return True
            if word == "load" and rest:
                return self._guarded(lambda: self._load_file(strip_full_stop(rest).strip("'\"")))
            if word == "add" and rest:
                return self._guarded(lambda: self._add(rest))
            if word == "at" and rest:
                return self._guarded(lambda: self._set_at(strip_full_stop(rest)))
        self.pending.append(line.rstrip("\n"))
        text = "\n".join(self.pending).strip()
        # its full stop as the reader sees it: a comment may follow it, a '.' inside a
        # comment or quotes is none
        end = full_stop_end(text)
        if end is None:
            self.state = ShellState.CONTINUING  # a goal spanning several lines
            return True
        self.pending = []
        self.state = ShellState.READY
        return self._guarded(lambda: self._run(text[:end]))

    def _guarded(self, action: Any) -> bool:
        try:
            action()
        except slr_sql.SLRSyntaxError as exc:
            self.echo_err(printable_syntax_error(exc))
        except (ValueError, OSError) as exc:
            self.echo_err(f"error: {exc}")
        except RecursionError:
            self.echo_err("error: the term is nested too deeply")
        except Exception as exc:  # SLRError, a database error: words, and the shell goes on
            self.echo_err(f"error: {error_words(exc)}")
        return True

    def _load_file(self, path: str) -> None:
        self.kb.load_file(path)
        # (named as slr load names a file: a name with a control character quoted, as writeq)
        self.echo(f"loaded {printable_name(path)}")

    def _add(self, event: str) -> None:
        self.kb.add(strip_full_stop(event))
        self.echo("added.")

    def _set_at(self, value: str) -> None:
        try:
            at = None if value in ("none", "off") else float(value)
        except ValueError:
            raise slr_sql.SLRError(f"at takes a number of seconds (or none), not "
                                   f"{printable_name(value)}") from None
        # refused here as every query would refuse it (nan), not echoed as a view and then
        # failing each goal; inf is a view queries take (every stored event)
        check_time_option("at", at)
        self.at = at
        self.echo(f"stream view: {'every stored event' if self.at is None else f'at {self.at:g}'}")

    # -- the program 'user' ----------------------------------------------------------------
    def _user_clauses(self) -> list[Any]:
        from .parser import parse_program

        infos = {(_info_field(i, "name")): i for i in _program_infos(self.kb)}
        info = infos.get(SHELL_PROGRAM)
        return parse_program(_info_field(info, "source"), SHELL_PROGRAM) if info else []

    def _set_user_program(self, texts: list[str]) -> None:
        if texts:
            self.kb.load("\n".join(texts), name=SHELL_PROGRAM, replace=True)
        elif SHELL_PROGRAM in {_info_field(i, "name") for i in _program_infos(self.kb)}:
            self.kb.unload(SHELL_PROGRAM)

    def _end_consult(self) -> None:
        text, self.consulted = "\n".join(self.consulted), []
        self.state = ShellState.READY
        if text.strip():
            self.kb.load(text, filename="user", name=SHELL_PROGRAM)
        self.echo(f"% consulted into the program '{SHELL_PROGRAM}'")

    def _assert(self, clause_text: str, first: bool) -> None:
        from .parser import parse_program

        # A full stop after a symbol character would join it (`:-.` is one atom).
        clause_text += " ." if clause_text[-1:] in set("+-*/\\^<>=~:.?@#&$") else "."
        parse_program(clause_text, "<assert>")   # a bad clause changes nothing
        if first:
            self._set_user_program([clause_text] + [c.text for c in self._user_clauses()])
        else:
            self.kb.load(clause_text, filename="<assert>", name=SHELL_PROGRAM)
        self.echo("true.")

    def _retract(self, pattern: Any) -> None:
        from .unify import undo, unify

        clauses = self._user_clauses()
        for i, clause in enumerate(clauses):
            if clause.head is None:
                continue
            term = (clause.head if clause.body == Atom("true") and not _is_clause(pattern)
                    else Struct(":-", (clause.head, clause.body)))
            trail: list = []
            if unify(pattern, term, trail):
                undo(trail, 0)
                self._set_user_program([c.text for j, c in enumerate(clauses) if j != i])
                self.echo("true.")
                return
            undo(trail, 0)
        self.echo("false.")

    def _listing(self, spec: Any) -> None:
        from .parser import parse_program

        if spec is None:
            clauses = self._user_clauses()
            if not clauses:
                self.echo(f"% the program '{SHELL_PROGRAM}' is empty")
            for clause in clauses:
                self.echo(clause.text)
            return
        if isinstance(spec, Struct) and spec.name == "/" and len(spec.args) == 2:
            name, arity = str(spec.args[0]), spec.args[1]
        else:
            name, arity = str(spec), None
        shown = 0
        for info in _program_infos(self.kb):
            for clause in parse_program(_info_field(info, "source"), _info_field(info, "name")):
                head = clause.head
                if isinstance(head, Struct) and head.name == "^" and len(head.args) == 2:
                    head = head.args[0]
                head_name = head.name if isinstance(head, Struct) else head
                head_arity = len(head.args) if isinstance(head, Struct) else 0
                if head is not None and str(head_name) == name and arity in (None, head_arity):
                    self.echo(f"{clause.text}   % {_info_field(info, 'name')}")
                    shown += 1
        if not shown:
            self.echo(f"% no clauses of {name}{'' if arity is None else f'/{arity}'}")

    def _programs(self) -> None:
        for info in _program_infos(self.kb):
            texts = _info_field(info, "texts") or 0
            self.echo(f"{_info_field(info, 'name')}: {texts} text{'s' if texts != 1 else ''}")

    def _command(self, text: str) -> bool:
        """A shell command written as a goal (assert, retract, listing, programs); False
        when ``text`` is an ordinary goal."""
        from .parser import parse_term

        match = re.fullmatch(r"(assertz?|asserta|retract)\s*\((.*)\)", strip_full_stop(text),
                             re.DOTALL)
        if match:
            parse_term(strip_full_stop(text), "<shell>")   # a syntax error points into the line
            inner = match.group(2).strip()
            if match.group(1) == "retract":
                self._retract(parse_term(inner, "<retract>")[0])
            else:
                if inner.startswith("(") and inner.endswith(")"):
                    inner = inner[1:-1].strip()
                self._assert(inner, first=match.group(1) == "asserta")
            return True
        goal = strip_full_stop(text)
        if goal in ("listing", "programs"):
            self._listing(None) if goal == "listing" else self._programs()
            return True
        if goal.startswith("listing(") and goal.endswith(")"):
            self._listing(parse_term(goal[len("listing("):-1], "<listing>")[0])
            return True
        if goal in ("[user]", "consult(user)"):
            self.state = ShellState.CONSULTING
            self.echo("% type clauses; end_of_file. or Ctrl-D ends")
            return True
        return False

    def _run(self, text: str) -> None:
        if text.startswith("explain "):
            self.echo(self.kb.explain(strip_full_stop(text[len("explain "):])))
            return
        if text.startswith(":-"):
            self.kb.load(text, filename="<shell>", name=SHELL_PROGRAM)
            self.echo("true.")
            return
        if self._command(text):
            return
        goal = strip_full_stop(text)
        from .parser import parse_term

        if _is_clause(parse_term(goal, "<shell>")[0]):
            raise slr_sql.SLRError("a clause typed at ?- is a goal, and (:-)/2 is no "
                                   "predicate: add it with assert((Head :- Body)). or [user].")
        for warning in (self.kb.goal_warnings(goal) if hasattr(self.kb, "goal_warnings") else []):
            self.echo_err(f"warning: {warning}")
        if self.ask is None or not hasattr(self.kb, "solutions"):
            answers = self.kb.query(goal, at=self.at)
            for line in answer_lines(answers):
                self.echo(line)
            return
        # (lazily: an answer is printed as it is found, so a goal with endless answers,
        # `repeat.`, shows its first at once and the next only when asked)
        self._one_at_a_time(self.kb.solutions(goal, at=self.at))

    def _raise_the_signal(self) -> None:
        """(A goal's search stopped by :meth:`stop_goal`) The exception of the signal that
        stopped it: ShellTerminated for SIGTERM or SIGHUP, else KeyboardInterrupt."""
        if self.terminating is not None:
            raise ShellTerminated(self.terminating) from None
        raise KeyboardInterrupt from None

    def _one_at_a_time(self, answers: Iterator[dict[str, Any]]) -> None:
        """SWI-Prolog's way: an answer, then the key pressed decides: the next or stop."""
        try:
            while True:
                self.running = answers   # (while it looks for an answer: stop_goal)
                try:
                    answer = next(answers)
                except StopIteration:
                    break
                except slr_sql.SLRError as exc:
                    if self.signalled and str(exc) == STOPPED_BY_CALLER:
                        self._raise_the_signal()
                    raise
                finally:
                    self.running = None
                if self.signalled:
                    # (the stop came after the search's last check: the answer found is not
                    # shown, the Ctrl-C or SIGTERM ends the goal now, not at the next key)
                    self._raise_the_signal()
                # (its unnamed variables named over the whole answer, then the values cut)
                answer = unnamed_variables_named(answer)
                shown = {k: abbreviated(v) for k, v in answer.items()}
                self.echo(answer_text(shown) if answer else "true", nl=False)
                while True:
                    try:
                        key = self.ask()
                    except EOFError:   # Ctrl-D: no more answers, as Enter
                        key = "\x04"
                    if key == "w":
                        self.echo("\n" + answer_text(answer), nl=False)
                        continue
                    break
                if key in (";", "n", "r", " ", "\t"):
                    self.echo(" ;")
                    continue
                self.echo(" .")
                return
            self.echo("false.")
        finally:
            self.signalled = False
            close = getattr(answers, "close", None)
            if close is not None:
                close()


class PipedInput:
    """The lines of a shell's standard input that is no terminal (a pipe, a file): its goals
    and, after each answer, the response to it, read from the same input as SWI-Prolog's
    top level reads it there (a line each).

    :meth:`response` is the shell's ``ask``: a line ``;`` (or ``n``, ``r``) asks for the next
    answer, ``w`` shows the answer in full, an empty line, ``.`` (or ``c``, ``a``) or the
    end of the input stops. Any other line stops the answers too and is not used up: it is
    the next goal (SWI-Prolog said "Unknown action" and ate it), so a script of goals, one a
    line, runs each goal to its first answer.

    >>> import io
    >>> piped = PipedInput(io.StringIO("  ;\\nw\\n\\nX = 1.\\n"))
    >>> [piped.response() for _ in range(4)], list(piped)
    ([';', 'w', '.', '.'], ['X = 1.\\n'])
    """

    NEXT = frozenset(";nr")
    STOP = frozenset(("", ".", "c", "a"))

    def __init__(self, stream: Any):
        self.stream = stream
        self.pushed_back: str | None = None

    def __iter__(self) -> Iterator[str]:
        return self

    def __next__(self) -> str:
        if self.pushed_back is not None:
            line, self.pushed_back = self.pushed_back, None
            return line
        line = self.stream.readline()
        if not line:
            raise StopIteration
        return line

    def response(self) -> str:
        """The response to an answer (see the class's text); EOFError at the end."""
        line = next(self, "")
        if not line:
            raise EOFError
        key = line.strip()
        if key in self.NEXT:
            return ";"
        if key == "w":
            return "w"
        if key not in self.STOP:
            self.pushed_back = line   # a goal, not a response: the shell reads it next
        return "."


def read_key(stream: Any = None) -> str:
    """One key pressed at the terminal ``stream`` (standard input): a character, or an
    escape sequence (an arrow key) whole. Ctrl-C raises KeyboardInterrupt, Ctrl-D EOFError.

    Keys typed ahead stay for what reads next: click's ``getchar`` read up to 32 bytes as
    one key (``;;`` pressed quickly was no ``;`` and stopped the answers, a line typed
    after the key went with it) and its raw mode discarded the keys typed while the goal
    ran (``TCSAFLUSH``).

    >>> import os, pty
    >>> main_end, terminal_end = pty.openpty()
    >>> _ = os.write(main_end, ";é\x1b[A;".encode())
    >>> terminal = os.fdopen(terminal_end)
    >>> [read_key(terminal) for _ in range(4)] == [";", "é", chr(27) + "[A", ";"]
    True
    """
    import select
    import termios
    import tty

    fd = (stream or sys.stdin).fileno()

    def ready() -> bool:   # the rest of a key comes in the same write
        return bool(select.select([fd], [], [], 0.05)[0])

    saved = termios.tcgetattr(fd)
    try:
        tty.setraw(fd, termios.TCSANOW)   # (TCSANOW: keys typed ahead are kept)
        key = os.read(fd, 1)
        if key and key[0] >= 0xC0:        # a UTF-8 character's lead byte
            more = 1 if key[0] < 0xE0 else 2 if key[0] < 0xF0 else 3
            while more and ready():
                key += os.read(fd, 1)
                more -= 1
        elif key == b"\x1b" and ready():
            key += os.read(fd, 1)
            if key[1:] in (b"[", b"O"):   # a control sequence: up to its final byte
                while ready():
                    key += os.read(fd, 1)
                    if 0x40 <= key[-1] <= 0x7E:
                        break
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)
    if key == b"\x03":
        raise KeyboardInterrupt
    if key in (b"", b"\x04"):
        raise EOFError
    return key.decode("utf-8", "replace")


def _is_clause(term: Any) -> bool:
    return isinstance(term, Struct) and term.name == ":-" and len(term.args) == 2


def _history_path() -> str:
    return os.environ.get("SLR_HISTORY") or os.path.join(os.path.expanduser("~"), ".slr_history")


def _completion_words(kb: KnowledgeBaseAPI) -> list[str]:
    """Predicate and event-type names for tab completion: the program's and the library's
    predicates (member, maplist, ...), the control constructs (findall, forall, ...), the
    store's event types, the shell's commands and the builtins -- never an internal helper,
    whose name begins with ``$`` (``'$skip_list'``, ``'$nth_gen'``): no one calls it by name.

    >>> import slr_sql
    >>> words = _completion_words(slr_sql.open(clock=slr_sql.ManualClock(0)))
    >>> {"member", "maplist", "findall", "atom_length"} <= set(words)
    True
    >>> [w for w in words if w.startswith("$")], "nth_gen" in words
    ([], False)
    """
    from .builtins import BUILTIN_NAMES
    from .engine import CONTROL

    words = {"assert", "asserta", "assertz", "retract", "listing", "programs", "explain",
             "load", "add", "help", "halt", "prev", "next"}
    engine = getattr(kb, "engine", None)
    for program in (getattr(engine, "program", None), getattr(engine, "library", None)):
        if program is not None:
            words |= {name for name, _ in list(program.preds) + list(program.temporal)}
    store = getattr(kb, "store", None)
    if store is not None:
        words |= {name for name, _ in store.event_types()}
    words |= {name for name, _ in BUILTIN_NAMES} | {name for name, _ in CONTROL}
    # (a name that needs quotes is not completed: it is typed with its quotes; member_/3 is
    # member/2's helper, named as in SWI-Prolog's library, which does not export it either)
    return sorted(w for w in words if not w.startswith("$") and w != "member_"
                  and re.fullmatch(r"[a-z][A-Za-z0-9_]*", w))


@main.command()
@click.argument("db", type=click.Path(dir_okay=False))
def shell(db: str) -> None:
    """Interactive goals and program text on DB (history in ~/.slr_history or $SLR_HISTORY)."""
    with _open(db, create=False) as kb:
        if not sys.stdin.isatty():
            # Piped input (scripts, tests): plain lines, no prompt, no history file; the
            # response to an answer is a line of the same input (PipedInput)
            piped = PipedInput(sys.stdin)
            session = Shell(kb, ask=piped.response)
            for line in piped:
                if not session.feed(line):
                    break
            if session.state == ShellState.CONSULTING:
                session.end_of_input()
            elif session.pending:
                _err("error: input ended inside an unfinished clause (missing full stop)")
            return
        from prompt_toolkit import PromptSession
        from prompt_toolkit.completion import Completer, Completion
        from prompt_toolkit.document import Document
        from prompt_toolkit.history import FileHistory

        class PredicateCompleter(Completer):
            """Completes the word before the cursor with the names known at that moment."""

            def get_completions(self, document: Document, complete_event: Any) -> Any:
                word = document.get_word_before_cursor(pattern=re.compile(r"[a-z][A-Za-z0-9_]*"))
                if not word:
                    return
                for name in _completion_words(kb):
                    if name.startswith(word) and name != word:
                        yield Completion(name, start_position=-len(word))

        session = Shell(kb, ask=read_key)
        prompt: PromptSession[str] = PromptSession(history=FileHistory(_history_path()),
                               completer=PredicateCompleter(), complete_while_typing=False)
        click.echo(f"slr shell on {printable_name(shown_location(db))} — `help` for commands, Ctrl-C stops a goal, "
                   f"Ctrl-D leaves")
        terminal = TerminalModes(sys.stdin)
        ended_by: int | None = None
        try:
            interactive(session, prompt, before_prompt=lambda: cooked_keys_typed_ahead(
                sys.stdin, prompt.app.input), on_terminate=terminal.silence_if_hung_up)
        except ShellTerminated as exc:
            ended_by = exc.signum
        finally:
            terminal.restore()
    if ended_by is not None:   # the store is closed: end as the signal's default would
        _die_of(ended_by)


class ShellTerminated(BaseException):
    """SIGTERM or SIGHUP reached the interactive shell (a BaseException, as
    KeyboardInterrupt: no ``except Exception`` of a goal's may keep it). The shell gives the
    terminal back, closes the store and ends as killed by ``signum``.

    >>> ShellTerminated(15).signum
    15
    """

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


class TerminalModes:
    """The modes of the terminal ``stream`` is (if it is one) when made, set again by
    :meth:`restore`: a shell ended by a signal while its line editor or the wait for a key
    held the terminal raw gives it back cooked, whether or not its parent resets it.

    >>> import io; TerminalModes(io.StringIO()).restore()   # no terminal: nothing to do
    """

    def __init__(self, stream: Any):
        import termios

        try:
            self.fd: int | None = stream.fileno()
            self.modes: list | None = termios.tcgetattr(self.fd)
        except (OSError, ValueError, AttributeError, termios.error):   # not a terminal
            self.fd = self.modes = None
        # the outputs that write to a terminal (stdout, stderr)
        self.outputs = [fd for fd in (1, 2) if os.isatty(fd)]

    def silence_if_hung_up(self) -> None:
        """When the terminal hung up (a read gives end of file, a write fails with EIO), point
        the outputs that wrote to it at /dev/null: what the shell still says on its way out
        (the line editor's last redraw) goes nowhere instead of failing."""
        import termios

        if self.fd is None:
            return
        try:
            termios.tcgetattr(self.fd)
            return
        except (OSError, termios.error):
            pass
        nowhere = os.open(os.devnull, os.O_WRONLY)
        try:
            for fd in self.outputs:
                os.dup2(nowhere, fd)
        finally:
            os.close(nowhere)

    def restore(self) -> None:
        import termios

        if self.fd is None or self.modes is None:
            return
        try:
            termios.tcsetattr(self.fd, termios.TCSADRAIN, self.modes)
        except (OSError, termios.error):   # hung up (SIGHUP): no terminal to give back
            pass


def _die_of(signum: int) -> None:
    """End this process as killed by ``signum`` (its default action), so that its parent
    learns why (a shell prints "Terminated", a supervisor sees the signal)."""
    import signal

    sys.stdout.flush()
    signal.signal(signum, signal.SIG_DFL)
    os.kill(os.getpid(), signum)
    sys.exit(128 + signum)   # (a signal whose default does not end the process)


class ShellInterrupts:
    """Where SIGINT (Ctrl-C in the cooked terminal) goes in the interactive shell.

    The line editor reads Ctrl-C as a key while it owns the terminal (raw), but around that
    the terminal is cooked: before its prompt is drawn, and after Enter while it takes its
    prompt down (asyncio.run's own SIGINT handler, installed while the editor's event loop
    runs, turned a Ctrl-C there into a cancelled prompt: the line typed was dropped without
    a word). Installed for the whole shell (so asyncio installs none), this handler

    * raises KeyboardInterrupt while a line is handled (the goal stops), unless it stopped
      the search for a local goal's next answer (``stop_goal``), which then raises it;
    * before the editor started (between two lines: a SIGINT sent with kill), keeps it for
      the editor, which takes it as its Ctrl-C key once it runs (raised there, it escaped
      the shell's loop, which had not reached the editor's call);
    * while the editor reads keys (a SIGINT sent with kill), hands it to the editor as its
      Ctrl-C key (raising inside the editor's event loop would land in one of its tasks);
    * once the editor took a line, keeps it for that line (:meth:`take`): its goal is
      interrupted before it starts.

    SIGTERM and SIGHUP (:meth:`terminate`) end the shell (:class:`ShellTerminated`): while the
    editor reads keys it is asked to exit with it, so that it first gives the terminal back
    as it found it (raised inside its event loop it would land in one of its tasks); before
    it started, it gets the request once it runs; otherwise (a goal, the wait for the key
    after an answer, whose raw mode ends as the exception leaves it) it is raised at once.

    ``app``: the editor's prompt_toolkit Application; ``stop_goal``: asked first when a
    SIGINT comes while a goal runs (:meth:`Shell.stop_goal`): True, the goal's search was
    stopped and ends by itself, so nothing is raised.

    >>> gate = ShellInterrupts(app=None); gate.editing(); gate.take()
    False
    """

    EDITING = "editing"    # inside the line editor's call, from before its prompt to after
    RUNNING = "running"    # a line is handled: Ctrl-C stops the goal

    def __init__(self, app: Any, stop_goal: Callable[..., bool] | None = None):
        self.app = app
        self.stop_goal = stop_goal
        self.state = self.EDITING
        self.started = False       # whether the editor ran for this line
        self.after_enter = False   # a Ctrl-C came after the editor took the line
        self.before_editor = False  # a Ctrl-C came before the editor ran: its Ctrl-C key
        self.terminated: int | None = None   # SIGTERM/SIGHUP came: the shell ends

    def __call__(self, signum: int, frame: Any) -> None:
        if self.state == self.RUNNING:
            if self.stop_goal is not None and self.stop_goal():
                return   # (the goal's search ends by the stop, in words of an interrupt)
            raise KeyboardInterrupt
        if not self.started:
            self.before_editor = True
            return
        app = self.app
        if app.is_running and not app.is_done and app.loop is not None:
            try:
                app.loop.call_soon_threadsafe(self._as_key)
                return
            except RuntimeError:   # its loop is closing: the line was taken
                pass
        self.after_enter = True

    def terminate(self, signum: int, frame: Any) -> None:
        """The SIGTERM and SIGHUP handler: the shell ends (see the class's text)."""
        self.terminated = signum
        if self.state == self.RUNNING:
            if self.stop_goal is not None:
                # a local goal's search is stopped too: raised inside a statement SQLite runs
                # (a function of several arguments it calls), the exception below is cleared
                # there and the goal went on in the interpreter; stopped, the search raises
                # it again itself
                self.stop_goal(signum)
            raise ShellTerminated(signum)
        if not self.started:
            return   # (editor_started asks the editor to exit; the loop checks, too)
        app = self.app
        if app.is_running and not app.is_done and app.loop is not None:
            try:
                app.loop.call_soon_threadsafe(self._exit_editor)
                return
            except RuntimeError:   # its loop is closing: the line was taken
                pass
        raise ShellTerminated(signum)

    def _exit_editor(self) -> None:
        if self.terminated is not None and self.app.is_running and not self.app.is_done:
            self.app.exit(exception=ShellTerminated(self.terminated))
        # (else the line was taken meanwhile: the loop raises before handling it)

    def check_terminated(self) -> None:
        """Raise :class:`ShellTerminated` if SIGTERM or SIGHUP came."""
        if self.terminated is not None:
            raise ShellTerminated(self.terminated)

    def _as_key(self) -> None:
        if self.app.is_running and not self.app.is_done:
            self.app.key_processor.send_sigint()
        else:   # the line was taken meanwhile: the Ctrl-C is its goal's
            self.after_enter = True

    def editing(self) -> None:
        """The line editor is called for the next line (a Ctrl-C kept so far was meant for
        a goal that has ended)."""
        self.state = self.EDITING
        self.started = False
        self.after_enter = False

    def editor_started(self) -> None:
        """(The editor's ``pre_run``.) A Ctrl-C kept from before reaches the editor as its
        Ctrl-C key, after the keys typed ahead of it."""
        self.started = True
        if self.terminated is not None:
            self.app.loop.call_soon(self._exit_editor)
            return
        if self.before_editor:
            self.before_editor = False
            self.app.loop.call_soon(self._as_key)

    def take(self) -> bool:
        """From now on a Ctrl-C stops the goal; whether one came after Enter already."""
        self.state = self.RUNNING
        came, self.after_enter = self.after_enter, False
        return came


def interactive(session: Shell, prompt: Any, echo: Any = click.echo,
                before_prompt: Callable[[], None] | None = None,
                on_terminate: Callable[[], None] | None = None) -> None:
    """The shell's loop over a prompt_toolkit ``PromptSession``: a line, then what it says,
    until ``halt.`` or Ctrl-D. Ctrl-C at the prompt drops the unfinished line; Ctrl-C after
    Enter (as the prompt is taken down, or read with the Enter as a key typed ahead) stops
    the goal before it starts; Ctrl-C during a goal stops it. ``before_prompt`` is called
    before each prompt (the terminal shell: :func:`cooked_keys_typed_ahead`). SIGTERM and
    SIGHUP end the loop with :class:`ShellTerminated` (see :class:`ShellInterrupts`), after
    ``on_terminate`` is called in the handler (the terminal shell: the outputs silenced when
    the terminal hung up).

    >>> from prompt_toolkit import PromptSession
    >>> from prompt_toolkit.input import create_pipe_input
    >>> from prompt_toolkit.output import DummyOutput
    >>> with create_pipe_input() as keys:
    ...     keys.send_text("X = 1.\\r\\x04")
    ...     interactive(Shell(slr_sql.open()), PromptSession(input=keys, output=DummyOutput()))
    X = 1
    """
    import signal

    gate = ShellInterrupts(prompt.app, session.stop_goal)

    def terminate(signum: int, frame: Any) -> None:
        if on_terminate is not None:
            on_terminate()
        gate.terminate(signum, frame)

    previous = {signal.SIGINT: signal.signal(signal.SIGINT, gate)}
    for signum in (signal.SIGTERM, signal.SIGHUP):
        previous[signum] = signal.signal(signum, terminate)
    try:
        while True:
            gate.editing()
            gate.check_terminated()
            if before_prompt is not None:   # (keys typed ahead while the terminal was cooked)
                before_prompt()
            try:
                # Ctrl-C at the prompt is a key (the terminal is raw); no signal handler of
                # prompt_toolkit's may outlive the prompt and swallow the Ctrl-C of a goal.
                line = prompt.prompt(session.prompt, handle_sigint=False,
                                     pre_run=gate.editor_started)
            except KeyboardInterrupt:   # at the prompt: drop the line
                session.interrupt()
                continue
            except EOFError:
                if session.end_of_input():
                    continue
                break
            gate.check_terminated()   # (it came as the editor took the line)
            try:
                came = gate.take()
                if _ctrl_c_typed_ahead(prompt.app.input) or came:
                    raise KeyboardInterrupt
                if not session.feed(line):
                    break
                gate.editing()
            except KeyboardInterrupt:   # during a goal, or before it began: stop it
                gate.editing()
                session.interrupt()
                echo("\n% interrupted")
        gate.check_terminated()   # (a hung-up terminal also ends the editor: end of file)
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def _ctrl_c_typed_ahead(editor_input: Any) -> bool:
    """Whether the keys the line editor read after Enter (typed ahead, kept for its next
    prompt) hold a Ctrl-C: it is taken out, with the keys before it (Ctrl-C drops them),
    and stops the goal of the line just entered."""
    from prompt_toolkit.input.typeahead import get_typeahead, store_typeahead
    from prompt_toolkit.keys import Keys

    keys = get_typeahead(editor_input)
    last = max((i for i, k in enumerate(keys) if k.key == Keys.ControlC), default=None)
    store_typeahead(editor_input, keys if last is None else keys[last + 1:])
    return last is not None


def cooked_keys_typed_ahead(stream: Any, editor_input: Any) -> None:
    r"""Hand the keys typed while the terminal was cooked (a goal running, a file loading)
    to the line editor before it takes the terminal raw, the terminal's end-of-file key
    (Ctrl-D) among them as the key it is.

    In cooked mode the terminal turns Ctrl-D into an end-of-file mark, which a raw read
    gives as a NUL byte: the key was lost and the shell stayed. Read now, still cooked, the
    mark is a read of no bytes, in its place among the lines typed around it; it goes to the
    editor as Ctrl-D, typed ahead. The terminal's settings are left as they are: a shell
    killed outright (SIGKILL) leaves no key disabled. (A Ctrl-D typed in the instant between
    this read and the editor's first is still a NUL byte to it.)

    Nothing happens when ``stream`` is no terminal or is raw already.

    >>> import os, types
    >>> from prompt_toolkit.input.typeahead import get_typeahead
    >>> typist, terminal = os.openpty()   # a terminal in its cooked (line) mode
    >>> _ = os.write(typist, b"p(X).\n\x04")  # a goal and Ctrl-D, typed while a goal ran
    >>> editor_input = types.SimpleNamespace(typeahead_hash=lambda: "shell")
    >>> with os.fdopen(terminal, "rb", buffering=0) as stream:
    ...     cooked_keys_typed_ahead(stream, editor_input)
    >>> [key.key for key in get_typeahead(editor_input)][-3:]
    ['.', <Keys.ControlJ: 'c-j'>, <Keys.ControlD: 'c-d'>]
    >>> os.close(typist)
    """
    import codecs
    import select
    import termios

    from prompt_toolkit.input.typeahead import get_typeahead, store_typeahead
    from prompt_toolkit.input.vt100_parser import Vt100Parser
    from prompt_toolkit.key_binding import KeyPress
    from prompt_toolkit.keys import Keys

    try:
        fd = stream.fileno()
        if not termios.tcgetattr(fd)[3] & termios.ICANON:
            return
    except (OSError, ValueError, termios.error):   # not a terminal
        return
    keys: list[Any] = []
    parser = Vt100Parser(keys.append)
    decoder = codecs.getincrementaldecoder("utf-8")(errors="surrogateescape")
    for _ in range(1000):   # (each read takes one line or one mark)
        try:
            if not select.select([fd], [], [], 0)[0]:
                break
            data = os.read(fd, 4096)
        except OSError:
            break
        if data:
            parser.feed(decoder.decode(data))
        else:   # the end-of-file mark: the Ctrl-D key
            parser.flush()
            keys.append(KeyPress(Keys.ControlD, "\x04"))
    parser.flush()
    if keys:
        store_typeahead(editor_input, get_typeahead(editor_input) + keys)


def _ros_command() -> click.Command:
    from .ros.cli import ros  # `slr ros` (its extra is imported on use)

    return ros


def _foxglove_command() -> click.Command:
    from .viz.cli import foxglove_command

    return foxglove_command


def _export_command() -> click.Command:
    from .viz.cli import export_command

    return export_command


def _fleet_command() -> click.Command:
    from .fleet import click_group  # `slr fleet push|status`

    return click_group()  # type: ignore[no-any-return]


def _serve_command() -> click.Command:
    from .service.cli import serve  # its body imports uvicorn when run

    return serve


# The commands defined in other modules, by name, each imported when first asked for (see
# SLRGroup): together their modules cost every other command ~8 ms of imports.
LAZY_COMMANDS: dict[str, Callable[[], click.Command]] = {
    "ros": _ros_command, "foxglove": _foxglove_command, "export": _export_command,
    "fleet": _fleet_command, "serve": _serve_command,
}


# ---------------------------------------------------------------------------------------------
# plot (timelines; the drawing is in slr_sql/plot.py)
# ---------------------------------------------------------------------------------------------

@main.command()
@click.argument("db", type=click.Path(dir_okay=False))
@click.argument("types", nargs=-1)
@click.option("--from", "start", type=float, default=None, help="Start of the time window.")
@click.option("--to", "end", type=float, default=None, help="End of the time window.")
@click.option("--value", "values", multiple=True, metavar="TYPE:ARG",
              help="Draw a numeric argument as a line, e.g. speed:1, seg:2[0], tf:3.pose[0][0].")
@click.option("--complex", "complex_types", multiple=True, metavar="TYPE",
              help="Mark TYPE as a complex event type (default: the store's own list, if any).")
@click.option("--by", "by", multiple=True, metavar="TYPE:ARG",
              help="A row and a color per value of this argument, e.g. seg:1 (a row per "
                   "object); value lines of TYPE split the same way.")
@click.option("--lag/--no-lag", "lags", default=None,
              help="Draw each event's arrival lag, end time -> arrival (default: when the "
                   "arrivals share the events' clock).")
@click.option("--internal", is_flag=True, help="Also the store's own types (slr_import/3, ...).")
@click.option("--relative/--absolute", "relative", default=None,
              help="Time axis in seconds since the window's start (default: for epoch times).")
@click.option("--query", "query_goal", default=None, metavar="GOAL",
              help="A row with GOAL's answers over time, GOAL asked with T at each --every "
                   "step, e.g. 'location(cup1, L)^T'.")
@click.option("--every", type=float, default=None, metavar="S",
              help="Seconds between the times --query asks its goal (default: 1/200 of the window).")
@click.option("--timeout", type=float, default=None, metavar="S",
              help="Give up after S seconds of --query asks (all of them together); nothing "
                   "is written.")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="The image to write: .png, .jpg, .svg or .pdf.")
@click.option("--size", default=None, metavar="WxH", help="Image size in pixels (default 1200 wide).")
@click.option("--dpi", type=int, default=100, show_default=True, help="Scales text and lines.")
@click.option("--title", default=None, help="Title above the rows (default: the DB's file name).")
def plot(db: str, types: tuple[str, ...], start: float | None, end: float | None,
         values: tuple[str, ...], complex_types: tuple[str, ...], by: tuple[str, ...],
         lags: bool | None, internal: bool, relative: bool | None, query_goal: str | None,
         every: float | None, timeout: float | None, output: str, size: str | None, dpi: int,
         title: str | None) -> None:
    """Draw the event histories of DB as a timeline image: one row per event TYPE (default:
    all but the store's own).

    Intervals are bars, points ticks, --value arguments lines, arrival lags orange lines;
    histories too long for the picture are aggregated per pixel column.
    """
    from .plot import (IMAGE_FORMATS, check_image_target, collect_timeline, draw_timeline,
                       parse_size)

    suffix = os.path.splitext(output)[1].lower()
    if suffix not in IMAGE_FORMATS:   # before any work: nothing is written
        raise slr_sql.SLRError(f"cannot write {output}: the suffix {suffix or '(none)'} names "
                               f"no image format; use {', '.join(IMAGE_FORMATS)}")
    check_image_target(output, db)
    if every is not None and query_goal is None:
        raise click.UsageError("--every goes with --query")
    if timeout is not None and query_goal is None:
        raise click.UsageError("--timeout goes with --query")
    check_time_option("--timeout", timeout, minimum=0.0)   # (as slr query's: inf is no limit)
    if not _is_url(db):   # (a server's store is drawn through its SQL, as kb.plot does)
        _check_existing_store(db)
    dimensions = parse_size(size) if size is not None else None
    with _open(db, create=False) as kb:
        if query_goal is not None and every is None:
            window = collect_timeline(kb, list(types) or None, start=start, end=end,
                                      internal=internal)
            every = (window.end - window.start) / 200
        collected = collect_timeline(
            kb, list(types) or None, start=start, end=end, values=values,
            complex_types=complex_types or None, size=dimensions, dpi=dpi,
            title=os.path.basename(db) if title is None else title, by=by, lags=lags,
            internal=internal, relative=relative,
            query=None if query_goal is None else strip_full_stop(query_goal), every=every,
            timeout=timeout)
    figure = draw_timeline(collected)
    from .plot import save_timeline

    save_timeline(figure, output)
    drawn = figure.slr_timeline
    n_rows = len(drawn.rows) + len(drawn.queries)
    click.echo(f"wrote {printable_name(output)} ({drawn.width}x{drawn.height} px, {n_rows} "
               f"row{'s' if n_rows != 1 else ''}"
               + (f", {len(drawn.series)} value line{'s' if len(drawn.series) != 1 else ''}"
                  if drawn.series else "") + ")")


# ---------------------------------------------------------------------------------------------
# subscribe (subscriptions)
# ---------------------------------------------------------------------------------------------

@main.command()
@click.argument("db", type=click.Path(dir_okay=False))
@click.argument("pattern")
@click.option("--where", default=None, help="A condition on the pattern's variables (an SLR "
              "goal), e.g. 'R > 60'.")
@click.option("--since", default="now", show_default=True, help="Only events whose end time "
              "is at or after S: 'now' or a time; an earlier time prints stored events first.")
@click.option("--until", type=float, default=None, help="Stop (exit 0) once every matching "
              "event up to U was printed: the event type is complete up to U.")
@click.option("--id", "sub_id", default=None, help="Durable: resume after the last event an "
              "earlier run with the same id printed.")
def subscribe(db: str, pattern: str, where: str | None, since: str, until: float | None,
              sub_id: str | None) -> None:
    """Print the events matching PATTERN (e.g. 'face(F, R)^T') as JSON lines as they arrive,
    one object per event with the pattern's variables. Ctrl-C or SIGTERM stops (exit 0)."""
    import signal
    import threading

    from .subscriptions import answer_json

    if not _is_url(db):
        _check_existing_store(db)
    since_value: Any = since.strip()
    if since_value != "now":
        try:
            since_value = float(since_value)
        except ValueError:
            raise slr_sql.SLRError(f"--since must be 'now' or a number, not {since!r}") from None
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):   # stop between two events, never inside one
        signal.signal(signum, lambda *_: stop.set())
    with _open(db, create=False) as kb:
        sub = kb.subscribe(strip_full_stop(pattern), where=where, since=since_value,
                           until=until, id=sub_id)
        try:
            while not stop.is_set():
                try:
                    answer = sub.get(timeout=0.2)
                except slr_sql.SLRTimeout:
                    if sub.closed:   # its end, not a wait: a where condition out of its limit
                        raise
                    continue
                if answer is None:       # until reached
                    break
                try:
                    sys.stdout.write(answer_json(answer) + "\n")
                    sys.stdout.flush()
                except BrokenPipeError:
                    # the reader went away (| head): status 1 and no word, as every command
                    # ends then (SLRGroup.invoke); the answer not written stays unhandled
                    # (a durable subscription delivers it again)
                    sub.close(ack=False)
                    raise
        finally:
            sub.close()


# ---------------------------------------------------------------------------------------------
# stats (event-history management)
# ---------------------------------------------------------------------------------------------

@main.command()
@click.argument("db")
def stats(db: str) -> None:
    """Print the file size, events stored per type and each buffer's counters."""
    from .buffers import format_stats
    from .store import EventStore

    if _is_url(db):
        with _open(db) as kb:
            click.echo(printable_text(kb.stats()["text"]))   # (the server's text: its names)
        return
    _check_existing_store(db)
    with EventStore(db) as store:
        click.echo(format_stats(store, db))


def _whole_one_liners(command: click.Command) -> None:
    """A command and every subcommand of a group (``slr ros``, ``slr fleet``, ...) list with
    their first sentence whole in their group's --help, as the top-level commands do."""
    if not command.short_help:
        command.short_help = one_liner(command)
    if isinstance(command, click.Group):
        for subcommand in command.commands.values():
            _whole_one_liners(subcommand)


for _command in main.commands.values():   # (last: after every command was added; the lazy
    _whole_one_liners(_command)            # ones when SLRGroup loads them)


if __name__ == "__main__":  # pragma: no cover
    main()
