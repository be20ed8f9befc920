"""Integers of more than 4,300 digits (Python's own limit of str() and int(); slr_sql's
integers go to MAX_INTEGER_BITS, about 78,900 digits, docs/language.md "Arithmetic"): the
interpreter computed them, but the CLI's answer line, the shell and the service's JSON
stopped at them ("ValueError: Exceeds the limit ... (this is a bug in slr_sql)" and
"integer too large to send")."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import httpx
import pytest

import slr_sql
from slr_sql.terms import MAX_INTEGER_BITS, int_text

from service_helpers import ServiceProcess

REPO = Path(__file__).resolve().parent.parent
BIG = 10 ** 5000
GOAL = "X is 10**5000, Y is X mod 7"


def slr(*args: str, stdin: str | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], capture_output=True,
                          text=True, timeout=120, input=stdin,
                          env={**os.environ, "PYTHONPATH": str(REPO)})


@pytest.fixture
def db(tmp_path):
    path = tmp_path / "robot.db"
    with slr_sql.open(path, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add("seen(cup1)^1")
    return path


def test_slr_query_prints_the_integer(db):
    result = slr("query", str(db), GOAL)
    assert result.returncode == 0, result.stderr
    assert result.stdout == f"X = {int_text(BIG)}, Y = {BIG % 7}\n"


def test_the_shell_prints_the_integer(db):
    result = slr("shell", str(db), stdin=GOAL + ".\n")
    assert result.returncode == 0, result.stderr
    assert f"X = {int_text(BIG)}" in result.stdout, result.stdout[-500:]
    assert "bug" not in result.stdout + result.stderr


def test_the_service_sends_and_takes_the_integer(db, tmp_path):
    with ServiceProcess(db) as server, slr_sql.connect(server.url) as remote, \
            slr_sql.open(db) as local:
        assert remote.query(GOAL) == local.query(GOAL) == [{"X": BIG, "Y": BIG % 7}]
        assert remote.query("Y is X mod 7", args={"X": BIG + 1}) == [{"X": BIG + 1,
                                                                     "Y": (BIG + 1) % 7}]
        too_big = "1" * (int(MAX_INTEGER_BITS * 0.302) + 10)
        response = httpx.post(server.url + "/query", timeout=30,
                              json={"goal": "Y = X", "args": {"X": {"$int": too_big}}})
        assert response.status_code == 400, response.text
        assert "integer too large" in response.json()["error"]["message"]
        assert server.healthy()


@pytest.mark.parametrize("radix, digit", [(3, "2"), (36, "z"), (10, "7")])
def test_a_radix_integer_of_more_than_4300_digits_is_read(radix, digit):
    """R'digits in a base that is no power of two: int(digits, R) has the 4,300-digit limit
    too, and the query failed with "ValueError: Exceeds the limit ..." in Python's words."""
    digits = digit * 5000
    with slr_sql.open(":memory:") as kb:
        answer = kb.query(f"X = {radix}'{digits}, Y is X mod 1000003")
    expected = 0
    for _ in digits:
        expected = (expected * radix + int(digit, 36)) % 1000003
    assert answer[0]["Y"] == expected
