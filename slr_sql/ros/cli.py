"""``slr ros import``, ``slr ros info`` and ``slr ros bridge`` (the ``slr_sql[ros]`` extra).

The group is attached to ``slr`` by slr_sql/cli.py. This module imports only click and
slr_sql at load time, so ``slr --help`` stays fast and works without the extra; each command
imports ``rosbags`` / ``yaml`` / ``rclpy`` when it runs and says in words what to install
when they are missing. Errors are :class:`slr_sql.SLRError`, which ``slr`` prints as
``error: ...`` with exit status 1.
"""
from __future__ import annotations

import os
import sys
from typing import Any

import click

import slr_sql

from ..printable import printable_name, printable_text
from . import EXTRA_HINT

__all__ = ["ros"]

MAX_REJECTIONS_SHOWN = 20


def _need_extra(command: str, exc: ImportError) -> slr_sql.SLRError:
    missing = getattr(exc, "name", None) or str(exc)
    return slr_sql.SLRError(f"slr ros {command} needs the ROS extra ({missing} is not "
                            f"installed): {EXTRA_HINT}")


def _load_mapping(path: str | None, command: str) -> Any:
    try:
        from .mapping import Mapping, load_mapping
        if path is None:
            return Mapping()
        import yaml  # noqa: F401 - the MAP reader needs it; fail here with the hint
    except ImportError as exc:
        raise _need_extra(command, exc) from None
    return load_mapping(path)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
def ros() -> None:
    """ROS: import bags, or bridge live ROS 2 topics into DB (needs slr_sql[ros])."""


def _remove_new_store(db: str) -> None:
    """Remove the files of a store this command created and could not fill (an import that
    failed before its first event): a failed command leaves nothing behind."""
    for suffix in ("", "-wal", "-shm", "-journal"):
        try:
            os.remove(db + suffix)
        except OSError:
            pass


@ros.command("import")
@click.argument("bag", type=click.Path())
@click.argument("db_argument", metavar="[DB]", required=False, type=click.Path(dir_okay=False))
@click.option("--db", "db_option", type=click.Path(dir_okay=False), default=None,
              help="The store (as for every other command; `slr ros import BAG DB` works too).")
@click.option("--map", "map_path", type=click.Path(), default=None,
              help="MAP file (YAML or pub_sub.xml): topics -> events. Default: /tf and "
                   "/tf_static only.")
@click.option("--all", "all_topics", is_flag=True,
              help="Also import every unmapped topic as an event named after the topic, with "
                   "the message as a term.")
@click.option("--batch", "batch_size", type=click.IntRange(min=1), default=None,
              help="Events per transaction (default 10000).")
def import_command(bag: str, db_argument: str | None, db_option: str | None,
                   map_path: str | None, all_topics: bool, batch_size: int | None) -> None:
    """Import BAG (rosbag1 .bag, rosbag2 directory, .mcap or .db3) into DB (--db DB).

    Importing the same bag again adds nothing; an interrupted import continues.
    Messages that give no event are reported and the exit status is 1.
    """
    if db_argument is not None and db_option is not None and db_argument != db_option:
        raise click.UsageError(f"two stores given: {db_argument} and --db {db_option}")
    db = db_option or db_argument
    if db is None:
        raise click.UsageError("no store: slr ros import BAG --db DB")
    from ..arguments import refuse_memory_store
    refuse_memory_store(db, "slr ros import")
    mapping = _load_mapping(map_path, "import")
    try:
        from .bag_import import DEFAULT_BATCH, import_bag
        import rosbags  # noqa: F401
    except ImportError as exc:
        raise _need_extra("import", exc) from None
    if not os.path.exists(bag):
        raise slr_sql.SLRError(f"no such bag: {bag}")
    from rich.console import Console
    from rich.markup import escape
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                               TimeRemainingColumn)

    console = Console(stderr=True)
    created = not os.path.lexists(db)
    started = False  # whether the import read its first message (events may be stored)
    try:
        # A recording's events are old: the store's clock follows the bag's record times
        # (each batch arrives when its last message was recorded), and the import learns
        # no delays (a batch's arrival is no message's latency; the wall clock made every
        # type months late, a LearnedDelayWarning each and the capped delay learned)
        clock = slr_sql.ManualClock(0.0)
        with slr_sql.open(db, clock=clock, max_learned_delay=0.0) as kb, Progress(
                TextColumn("[progress.description]{task.description}"), BarColumn(),
                MofNCompleteColumn(), TimeRemainingColumn(), console=console,
                transient=True) as bar:
            # (the description is rich markup: the bag's name is text, never markup)
            name = printable_name(os.path.basename(os.path.normpath(bag)))
            task = bar.add_task(f"importing {escape(name)}", total=None)

            def progress(done: int, total: int) -> None:
                nonlocal started
                started = started or done > 0
                bar.update(task, completed=done, total=total)

            report = import_bag(kb, bag, mapping, all_topics=all_topics, progress=progress,
                                batch_size=batch_size or DEFAULT_BATCH, clock=clock)
    except Exception:
        # A MAP that does not fit the bag, a bag that cannot be read: no empty store is left
        # behind. A store that got events keeps them (a later run continues the import).
        if created and not started:
            _remove_new_store(db)
        raise
    _print_report(report, bag)
    if report.rejected or report.short:
        sys.exit(1)


def _print_report(report: Any, bag: str) -> None:
    from rich.console import Console
    from rich.table import Table

    if report.topics:
        table = Table("topic", "type", "event", "messages", "events", "already imported")
        for topic, t in sorted(report.topics.items()):
            table.add_row(printable_name(topic), printable_name(t.msgtype), printable_name(t.event),
                          str(t.messages), str(t.events), str(t.skipped))
        # (markup off: a topic named "[red]..." is printed as it is, not styled)
        Console(highlight=False, markup=False,
                width=None if sys.stdout.isatty() else 200).print(table)
    if report.unmapped:
        click.echo("not imported (no mapping; --all imports them): "
                   + ", ".join(map(printable_name, report.unmapped)))
    if report.missing:
        click.echo(f"mapped but not in the bag: {', '.join(map(printable_name, report.missing))}")
    for rejection in report.rejected[:MAX_REJECTIONS_SHOWN]:
        click.echo(printable_text(f"{bag}: {rejection}"), err=True)
    if len(report.rejected) > MAX_REJECTIONS_SHOWN:
        click.echo(f"{printable_name(bag)}: ... and {len(report.rejected) - MAX_REJECTIONS_SHOWN} more rejected "
                   f"messages", err=True)
    for topic, (counted, read) in sorted(report.short.items()):
        click.echo(f"{printable_name(bag)}: {printable_name(topic)}: the bag counts {counted} messages, {read} could be read "
                   f"(the bag is damaged or cut short)", err=True)
    click.echo(f"imported {report.events} event{'s' if report.events != 1 else ''} from "
               f"{report.messages} message{'s' if report.messages != 1 else ''}"
               + (f" ({report.skipped} already imported)" if report.skipped else "")
               + (f", {len(report.rejected)} rejected" if report.rejected else "")
               + f" [{printable_name(report.bag_id)}]")


@ros.command("info")
@click.argument("bag", type=click.Path())
@click.option("--map-only", is_flag=True,
              help="Print only the draft MAP (YAML), e.g. to redirect into a file.")
@click.option("--json", "as_json", is_flag=True, help="The summary as JSON (no draft MAP).")
def info_command(bag: str, map_only: bool, as_json: bool) -> None:
    """Topics of BAG (type, messages, time span), the frames in /tf and /tf_static, and a
    draft MAP for the topics (YAML, to edit and pass to `slr ros import --map`)."""
    try:
        import rosbags  # noqa: F401

        from .bag_info import bag_info, draft_map
    except ImportError as exc:
        raise _need_extra("info", exc) from None
    info = bag_info(bag)
    for t in info.topics:
        if t.read is not None and t.read < t.count:
            click.echo(f"warning: {printable_name(t.topic)}: the bag counts {t.count} messages, {t.read} could "
                       f"be read (the bag is damaged or cut short)", err=True)
        if t.undecodable:
            click.echo(f"warning: {printable_name(t.topic)}: {t.undecodable} of {t.count} messages do not "
                       f"decode (left out of the frames below; slr ros import rejects each "
                       f"with its reason)", err=True)
    if as_json:
        click.echo(info.as_json())
        return
    if map_only:
        click.echo(draft_map(info), nl=False)
        return
    from rich.console import Console
    from rich.table import Table

    # (markup off: a topic named "[red]..." is printed as it is, not styled)
    console = Console(highlight=False, markup=False, width=None if sys.stdout.isatty() else 200)

    def when(t: float | None) -> str:
        return "" if t is None else f"{t:.3f}"

    click.echo(f"bag:       {printable_name(info.path)} [{printable_name(info.bag_id)}]")
    click.echo(f"messages:  {info.count}")
    click.echo(f"time span: {when(info.start)} .. {when(info.end)} ({info.duration:.3f} s)")
    table = Table("topic", "type", "messages", "first", "last")
    for t in info.topics:
        table.add_row(printable_name(t.topic), printable_name(t.msgtype), str(t.count),
                      when(t.first), when(t.last))
    console.print(table)
    if info.frames:
        frames = Table("topic", "parent", "child", "transforms", "first stamp", "last stamp")
        for e in info.frames:
            frames.add_row(printable_name(e.topic), printable_name(e.parent), printable_name(e.child),
                           str(e.count), when(e.first), when(e.last))
        console.print(frames)
    else:
        click.echo("no transforms in /tf or /tf_static")
    click.echo("\n# ---- draft MAP (slr ros info BAG --map-only > robot.yaml) ----")
    click.echo(draft_map(info), nl=False)


@ros.command("bridge", context_settings={"ignore_unknown_options": True})
@click.argument("db", type=click.Path(dir_okay=False))
@click.option("--map", "map_path", type=click.Path(), default=None,
              help="MAP file (YAML or pub_sub.xml). Default: /tf and /tf_static only.")
@click.option("--all", "all_topics", is_flag=True,
              help="Also store every other topic, as `slr ros import --all` does.")
@click.option("--node-name", default="slr_bridge", show_default=True, help="The ROS node name.")
@click.option("--synchronous", type=click.Choice(["NORMAL", "FULL"]), default="NORMAL",
              show_default=True,
              help="SQLite durability: NORMAL survives a crash of the process, FULL also a "
                   "power cut (an fsync per message).")
@click.argument("ros_args", nargs=-1, type=click.UNPROCESSED)
def bridge_command(db: str, map_path: str | None, all_topics: bool, node_name: str,
                   synchronous: str, ros_args: tuple[str, ...]) -> None:
    """Run a ROS 2 node storing mapped topics in DB as events, until SIGINT or SIGTERM.

    ROS arguments may follow: --ros-args -p map:=robot.yaml -p all_topics:=true
    -r __node:=name --params-file params.yaml (the parameters map and all_topics).
    """
    if ros_args and ros_args[0] != "--ros-args":
        raise slr_sql.SLRError(f"unexpected argument {ros_args[0]!r} (ROS arguments start with "
                               f"--ros-args)")
    mapping = _load_mapping(map_path, "bridge")
    try:
        import rosbags  # noqa: F401

        from .bridge import run_bridge
    except ImportError as exc:
        raise _need_extra("bridge", exc) from None
    sys.exit(run_bridge(db, mapping, all_topics=all_topics, node_name=node_name,
                        synchronous=synchronous, ros_args=list(ros_args),
                        mapping_given=map_path is not None))
