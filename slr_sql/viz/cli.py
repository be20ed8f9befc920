"""``slr foxglove DB`` (a live Foxglove view) and ``slr export DB FILE.mcap``.

Attached to ``slr`` by slr_sql/cli.py; the foxglove-sdk and mcap packages are imported
when a command runs, with a hint naming the extra when they are missing.
"""
from __future__ import annotations

import signal
import sys
import threading

import click

import slr_sql

from ..printable import printable_name
from ..store import refuse_no_store

__all__ = ["foxglove_command", "export_command"]


def _store_for_view(db: str) -> tuple:
    """A knowledge base on ``db`` (migrations, refusal of non-stores) and the store the view
    follows from its thread."""
    refuse_no_store(db)
    kb = slr_sql.open(db)
    return kb, kb.store


@click.command("foxglove")
@click.argument("db", type=click.Path(dir_okay=False))
@click.option("--host", default="127.0.0.1", show_default=True,
              help="Interface to listen on (0.0.0.0: every interface).")
@click.option("--port", default=8765, type=click.IntRange(0, 65535), show_default=True,
              help="TCP port (0: any free port; the line printed at start names it).")
@click.option("--poll", default=0.002, type=click.FloatRange(0.0005, 10.0), show_default=True,
              help="Seconds between two looks at the store for new events.")
@click.option("--message-max", default=64 * 1024, type=click.IntRange(1024, 1 << 30),
              show_default=True, metavar="BYTES",
              help="Largest message sent (larger ones are left out, said once per topic); a "
                   "slow client holds at most 64 MiB of messages, or one if it is larger.")
def foxglove_command(db: str, host: str, port: int, poll: float, message_max: int) -> None:
    """Serve DB to Foxglove (WebSocket, foxglove.websocket.v1) until SIGINT or SIGTERM:
    every event type a channel, new events live, tf as foxglove.FrameTransforms."""
    from .foxglove_live import FoxgloveView, forward_sdk_log

    # the server's start, clients connecting and leaving, what a client sent that the
    # protocol refuses: one line each on stderr
    forward_sdk_log(lambda level, text: click.echo(f"foxglove: {text}", err=True))
    kb, store = _store_for_view(db)
    try:
        view = FoxgloveView(store, host=host, port=port, poll=poll,
                            log=lambda text: click.echo(text, err=True),
                            message_max_bytes=message_max).start()
    except OSError as exc:
        kb.close()
        raise slr_sql.SLRError(f"cannot listen on {host}:{port}: {exc}") from None
    except BaseException:   # FoxgloveCannotListen, ...: said by the caller
        kb.close()
        raise
    click.echo(f"foxglove: ws://{host}:{view.port} ({len(view.channels)} event types; "
               f"open it in Foxglove: Open connection -> Foxglove WebSocket)", err=False)
    sys.stdout.flush()
    done = threading.Event()

    def stop(signum: int, frame: object) -> None:
        done.set()

    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    try:
        while not done.wait(0.5):
            pass
    finally:
        view.close()
        kb.close()
    click.echo(f"foxglove: stopped after {view.sent} events")


@click.command("export")
@click.argument("db", type=click.Path(dir_okay=False))
@click.argument("file", type=click.Path(dir_okay=False))
@click.argument("types", nargs=-1)
@click.option("--from", "start", type=float, default=None,
              help="Only events ending at or after this time (seconds).")
@click.option("--to", "end", type=float, default=None,
              help="Only events ending at or before this time (seconds).")
def export_command(db: str, file: str, types: tuple[str, ...], start: float | None,
                   end: float | None) -> None:
    """Write the events of DB to FILE (MCAP; Foxglove opens it, `slr ros import` reads it
    back): every event type, or the TYPEs given (name/arity, or name for every arity)."""
    import math

    from .mcap_export import export_mcap

    for option, value in (("--from", start), ("--to", end)):
        if value is not None and not math.isfinite(value):
            raise slr_sql.SLRError(f"{option} must be a finite number of seconds")
    refuse_no_store(db)
    # (FILE standard output, /dev/stdout: the summary goes to standard error, not into it)
    summary_to_stderr = _is_standard_output(file)
    with slr_sql.open(db) as kb:
        try:
            report = export_mcap(kb.store, file, start, end, types)
        except OSError as exc:
            raise slr_sql.SLRError(f"cannot write {file}: {exc.strerror or exc}") from None
    for (name, arity), n in sorted(report.per_type.items()):
        click.echo(f"{printable_name(name)}/{arity}: {n}", err=summary_to_stderr)
    click.echo(f"exported {report.messages} event{'s' if report.messages != 1 else ''} "
               f"to {printable_name(file)}", err=summary_to_stderr)


def _is_standard_output(file: str) -> bool:
    """Whether ``file`` names the file this process's standard output is (``/dev/stdout``,
    ``/proc/self/fd/1``, the pipe or terminal it writes to).

    >>> _is_standard_output("/no/such/file")
    False
    """
    import os

    try:
        named, own = os.stat(file), os.fstat(sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        return False
    return (named.st_dev, named.st_ino) == (own.st_dev, own.st_ino)
