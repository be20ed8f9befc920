"""PostgreSQL URLs as libpq users write them (docs/postgres.md): the local server's socket
with no host before the path (``postgresql:///db?host=DIR``), and a password given as a
parameter, which no message may show."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from urllib.parse import parse_qsl, urlsplit

import pytest

import slr_sql
from slr_sql.store.postgres import split_url

REPO = Path(__file__).resolve().parent.parent


def without_host_part(url: str) -> str:
    """``postgresql://user:@/db?host=DIR`` as ``postgresql:///db?host=DIR&user=user``."""
    parts = urlsplit(url)
    query = dict(parse_qsl(parts.query))
    query["user"] = parts.username or "postgres"
    return f"postgresql://{parts.path}?" + "&".join(f"{k}={v}" for k, v in query.items())


def test_a_url_with_no_host_before_the_path_opens_the_store(postgres_url):
    """urlunsplit wrote ``postgresql:/db?host=...`` (one slash), which libpq does not read
    as a URL: "invalid connection option"."""
    url = without_host_part(postgres_url)
    assert url.startswith("postgresql:///slr_test_"), url
    with slr_sql.open(url, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add("seen(cup1)^1")
    with slr_sql.open(postgres_url) as kb:
        assert kb.query("seen(X)^T") == [{"X": slr_sql.Atom("cup1"), "T": 1.0}]


@pytest.mark.parametrize("url, conninfo", [
    ("postgresql:///db?host=/run/pg&schema=fleet", "postgresql:///db?host=%2Frun%2Fpg"),
    ("postgres://u@/db?host=/tmp", "postgresql://u@/db?host=%2Ftmp"),
    ("postgresql://h:5433/db", "postgresql://h:5433/db"),
    ("postgresql://", "postgresql://"),
])
def test_split_url_keeps_the_two_slashes(url, conninfo):
    assert split_url(url)[0] == conninfo


@pytest.mark.parametrize("secret_part", [
    "password=Hunter2secret", "sslpassword=Hunter2secret", "PASSWORD=Hunter2secret"])
def test_a_password_given_as_a_parameter_is_not_shown(tmp_path, secret_part):
    url = f"postgresql:///nowhere?host={tmp_path}&{secret_part}"
    with pytest.raises(slr_sql.SLRError) as caught:
        slr_sql.open(url)
    assert "Hunter2secret" not in str(caught.value)
    assert "***" in str(caught.value)
    result = subprocess.run([sys.executable, "-m", "slr_sql", "query", url, "p(X)"],
                            capture_output=True, text=True, timeout=120,
                            env={**os.environ, "PYTHONPATH": str(REPO)})
    assert result.returncode != 0
    assert "Hunter2secret" not in result.stderr + result.stdout
    assert "cannot connect" in result.stderr, result.stderr


@pytest.mark.parametrize("userinfo", [
    "robot:Hunter2@secret@", "robot:Hun@ter2/se@cret@", "robot:Hunter2%40secret@"])
def test_no_part_of_a_password_with_an_at_sign_is_shown(tmp_path, userinfo):
    """A password holding '@' unescaped (libpq's URL wants %40): the user's part ends at the
    last '@' before the host, and nothing of it up to there was to be shown."""
    url = f"postgresql://{userinfo}nowhere.invalid/db?host={tmp_path}"
    with pytest.raises(slr_sql.SLRError) as caught:
        slr_sql.open(url)
    for part in ("Hunter2", "secret", "cret", "ter2"):
        assert part not in str(caught.value)
    assert "robot:***@" in str(caught.value)


@pytest.mark.parametrize("secret_part", [
    "pass%77ord=Hunter2secret", "%70assword=Hunter2secret", "sslpass%77ord=Hunter2secret"])
def test_a_password_parameter_with_an_escaped_name_is_not_shown(tmp_path, secret_part):
    """libpq decodes a parameter's name as its value (``pass%77ord`` is ``password``), and so
    does split_url: such a password reached the server and showed in the message as written."""
    url = f"postgresql:///nowhere?host={tmp_path}&{secret_part}"
    with pytest.raises(slr_sql.SLRError) as caught:
        slr_sql.open(url)
    assert "Hunter2secret" not in str(caught.value)
    assert "***" in str(caught.value)


def test_a_password_parameter_holding_a_hash_sign_is_hidden_whole(tmp_path):
    """A '#' written unescaped in ``?password=`` ends the URL's query for split_url, and the
    message showed the rest of what the user wrote as the password."""
    url = f"postgresql:///nowhere?host={tmp_path}&password=Hunter2#secretpart"
    with pytest.raises(slr_sql.SLRError) as caught:
        slr_sql.open(url)
    assert "Hunter2" not in str(caught.value) and "secretpart" not in str(caught.value)


def test_a_password_libpq_cannot_decode_is_not_shown_in_its_words(tmp_path):
    """libpq refuses a bad %-escape quoting the token: "invalid percent-encoded token:
    \"Hunter2%zzsecret\"", the password itself, in slr's "cannot connect (...)"."""
    url = f"postgresql://robot:Hunter2%zzsecret@/nowhere?host={tmp_path}"
    with pytest.raises(slr_sql.SLRError) as caught:
        slr_sql.open(url)
    assert "Hunter2" not in str(caught.value) and "secret" not in str(caught.value)
    assert "robot:***@" in str(caught.value)


def test_slr_serve_does_not_print_the_password_of_its_store(postgres_url, tmp_path):
    """``slr serve: DB on http://...`` printed DB as given, password and all, on the
    standard output a service manager keeps in its log."""
    from service_helpers import ServiceProcess

    url = without_host_part(postgres_url) + "&password=Hunter2secret"
    with ServiceProcess(url, log=tmp_path / "server.log") as server:
        assert server.first_line.startswith("slr serve: postgresql:///slr_test_"), \
            server.first_line
        assert "password=***" in server.first_line, server.first_line
        assert "Hunter2secret" not in server.first_line
        assert server.healthy()
    assert "Hunter2secret" not in server.log.read_text()


def test_slr_fleet_push_names_a_robot_store_on_postgresql_without_its_password(
        postgres_url, tmp_path):
    url = without_host_part(postgres_url) + "&password=Hunter2secret"
    with slr_sql.open(url, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add("seen(cup1)^1")
    result = subprocess.run(
        [sys.executable, "-m", "slr_sql", "fleet", "push", url, str(tmp_path / "fleet.db")],
        capture_output=True, text=True, timeout=120, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert result.returncode == 1, result.stderr
    assert "has no robot name" in result.stderr, result.stderr
    assert "password=***" in result.stderr, result.stderr
    assert "Hunter2secret" not in result.stderr + result.stdout


def test_slr_stats_of_a_postgresql_store_says_what_its_space_is_without_the_password(
        postgres_url):
    """It printed ``file postgresql://...?password=...: N bytes = N bytes database + 0 bytes
    WAL``: the URL as given, and a file and a WAL the store does not have."""
    url = without_host_part(postgres_url) + "&password=Hunter2secret"
    with slr_sql.open(url, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add("seen(cup1)^1")
    result = subprocess.run([sys.executable, "-m", "slr_sql", "stats", url],
                            capture_output=True, text=True, timeout=120,
                            env={**os.environ, "PYTHONPATH": str(REPO)})
    assert result.returncode == 0, result.stderr
    first = result.stdout.splitlines()[0]
    assert first.startswith("store postgresql:///slr_test_") and "password=***" in first, first
    assert "in its schema's tables and indexes" in first and "WAL" not in first, first
    assert "Hunter2secret" not in result.stdout + result.stderr
    assert "  seen/1: 1 stored" in result.stdout


@pytest.mark.parametrize("url", ["POSTGRESQL://robot:Hunter2secret@db/x",
                                 "Postgres://robot:Hunter2secret@db/x",
                                 "mysql://robot:Hunter2secret@db/x"])
def test_a_url_of_another_spelling_is_no_store_and_its_password_is_not_shown(tmp_path, url):
    """libpq reads only postgresql:// and postgres:// in lower case; another scheme was taken
    as a file path (the folder "POSTGRESQL:") and the message showed it, password and all."""
    with pytest.raises(slr_sql.SLRError) as caught:
        slr_sql.open(url)
    assert "Hunter2secret" not in str(caught.value) and "not a store" in str(caught.value)
    for command in (["query", url, "p(X)"], ["add", url, "p(1)^1"]):
        result = subprocess.run([sys.executable, "-m", "slr_sql", *command], cwd=tmp_path,
                                capture_output=True, text=True, timeout=120,
                                env={**os.environ, "PYTHONPATH": str(REPO)})
        assert result.returncode != 0 and "not a store" in result.stderr, result.stderr
        assert "Hunter2secret" not in result.stderr + result.stdout
    assert not list(tmp_path.iterdir())        # no folder "POSTGRESQL:" made
