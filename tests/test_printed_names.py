r"""Names a stranger controls never reach the terminal raw (slr_sql/printable.py, docs/api.md).

A store, a bag, an MCAP file or an example file may hold event type names, argument atoms,
topics, program names and lines with ESC (an escape sequence: here one that sets the
terminal's title), CR, C1 controls or a bidi override. Every human-readable output of the CLI
prints such a character as SWI-Prolog's writeq escapes it (a name: quoted as writeq quotes
the atom); csv, tsv and json keep their own rules. Each command runs in a subprocess.
"""
from __future__ import annotations

import subprocess
import sys
import unicodedata

import pytest
from service_helpers import slr_env

import slr_sql
from slr_sql.terms import String

# ESC ] 0 ; ... BEL sets the terminal's title; CR rewrites the line; CSI in its C1 form;
# U+202E draws what follows right to left
HOSTILE = "x\x1b]0;owned\x07\r\x9b\u202ey"
SHOWN = "x\\x1B\\]0;owned\\a\\r\\x9B\\\\x202E\\y"     # as writeq writes it inside quotes


def slr(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], capture_output=True,
                          text=True, env=slr_env(), timeout=120)


def undrawn(text: str) -> list[str]:
    """The characters of ``text`` a terminal would not draw as themselves (not \n)."""
    return sorted({f"U+{ord(c):04X}" for c in text if c != "\n"
                   and unicodedata.category(c) in ("Cc", "Cf", "Zl", "Zp", "Co", "Cn")})


def printed(done: subprocess.CompletedProcess) -> str:
    out = done.stdout + done.stderr
    assert "Traceback" not in out, out
    assert undrawn(out) == [], (undrawn(out), out)
    return out


@pytest.fixture
def hostile_store(tmp_path):
    db = tmp_path / "h.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(100)) as kb:
        kb.add_event("ev" + HOSTILE, ["a" + HOSTILE, String("s" + HOSTILE)], start=1.0, end=1.0)
        kb.add_event("ok", ["a" + HOSTILE, String("s" + HOSTILE)], start=1.0, end=1.0)
        kb.load("p(X) :- ok(X, _)^_.", name="prog" + HOSTILE)
    return db


def test_stats_quotes_a_type_name_holding_control_characters(hostile_store):
    out = printed(slr("stats", str(hostile_store)))
    assert f"'ev{SHOWN}'/2: 1 stored" in out and "\n  ok/2: 1 stored" in out


def test_describe_quotes_the_type_name(hostile_store):
    out = printed(slr("describe", str(hostile_store)))
    assert f"'ev{SHOWN}'/2  (table " in out and "\nok/2  (table ok)" in out


def test_describe_of_an_unknown_type_escapes_the_names_in_its_error(hostile_store):
    done = slr("describe", str(hostile_store), "no" + HOSTILE)
    assert done.returncode == 1
    assert "error: no event type" in printed(done)


def test_query_answers_escape_atoms_and_strings(hostile_store):
    out = printed(slr("query", str(hostile_store), "ok(X, Y)^T"))
    assert out == f"X = 'a{SHOWN}', Y = \"s{SHOWN}\", T = 1.0\n"
    out = printed(slr("query", str(hostile_store), "ev" + HOSTILE.replace("\r", "") + "(X, Y)^T"))
    assert "unexpected character" in out


def test_query_json_is_json(hostile_store):
    # JSON's own rule: C0 controls escaped (\u001b); C1 and bidi characters are valid JSON
    # text and left to the JSON reader
    done = slr("query", "--json", str(hostile_store), "ok(X, Y)^T")
    assert '"X":"ax\\u001b]0;owned\\u0007\\r' in done.stdout


def test_sql_box_table_escapes_cells_and_takes_no_markup(hostile_store):
    out = printed(slr("sql", "--table", str(hostile_store),
                      'SELECT arg1, \'[red]styled\' AS "[bold]c" FROM ok'))
    assert "ax\\x1B\\]0;owned\\a\\r\\x9B\\\\x202E\\y" in out
    assert "[red]styled" in out and "[bold]c" in out


def test_programs_quotes_the_program_name(hostile_store):
    out = printed(slr("programs", str(hostile_store)))
    assert out.startswith(f"'prog{SHOWN}': 1 text")


def test_export_quotes_the_type_names_it_counts(hostile_store, tmp_path):
    out = printed(slr("export", str(hostile_store), str(tmp_path / "o.mcap")))
    assert f"'ev{SHOWN}'/2: 1\nok/2: 1\n" in out


def test_ros_info_and_import_of_hostile_channels(hostile_store, tmp_path):
    mcap = tmp_path / "o.mcap"
    assert slr("export", str(hostile_store), str(mcap)).returncode == 0
    out = printed(slr("ros", "info", str(mcap)))
    assert f"'/ev{SHOWN}/2'" in out
    out = printed(slr("ros", "import", str(mcap), "--db", str(tmp_path / "back.db")))
    assert f"'ev{SHOWN}/2'" in out and "imported 2 events" in out


def test_a_syntax_error_in_a_stranger_s_file_escapes_the_line_and_keeps_the_caret(tmp_path):
    program = tmp_path / "bad.slr"
    program.write_text("p('a\x1b]0;owned\x07b') :- q q.\n", encoding="utf-8")
    done = slr("load", str(tmp_path / "x.db"), str(program))
    out = printed(done)
    assert done.returncode == 1 and "operator expected" in out
    line, caret = [line for line in out.splitlines() if line.startswith("    ")][:2]
    assert line == "    p('a\\x1B\\]0;owned\\ab') :- q q."
    assert caret.index("^") == line.rindex("q")   # still under the second q


def test_run_escapes_the_goals_of_an_example_file(tmp_path):
    example = tmp_path / "ex.slr"
    example.write_text("%% events\nseen(a)^1\n%% query: seen(X)^T, Y = 'q\x1b]0;owned\x07'\n"
                       "%% expect: X = a, T = 1.0, Y = q\n", encoding="utf-8")
    out = printed(slr("run", str(example)))
    assert "'q\\x1B\\]0;owned\\a'" in out


def test_warnings_of_the_plot_library_are_escaped(hostile_store, tmp_path):
    # matplotlib warns that the font has no glyph for ESC, quoting the character
    out = printed(slr("plot", str(hostile_store), "-o", str(tmp_path / "p.png")))
    assert "wrote " in out


def test_fleet_status_quotes_a_robot_name_a_fleet_file_edited_by_hand_holds(tmp_path):
    import sqlite3

    robot, fleet = tmp_path / "robot.db", tmp_path / "fleet.db"
    with slr_sql.open(robot, robot="r1", clock=slr_sql.ManualClock(100)) as kb:
        kb.add("seen(a)^1")
    assert slr("fleet", "push", str(robot), str(fleet)).returncode == 0
    with sqlite3.connect(fleet) as conn:    # a name no way in takes (check_robot_name)
        conn.execute("UPDATE slr_fleet_robots SET robot = ?", ("r" + HOSTILE,))
    conn.close()
    out = printed(slr("fleet", "status", str(fleet)))
    assert f"'r{SHOWN}'" in out
