"""`slr programs`, `slr unload`, `slr describe`: seeing what a store holds (real subprocesses)."""
from __future__ import annotations

import datetime
import re
from pathlib import Path

import pytest
from conftest import copy_of_store
from test_cli import slr

PROGRAM = """\
color(O, C)^T :- prev(obj(O, _, C)^Z, T).
near(O) :- obj(O, _, _)^_.
big(X) <- seen(X)^T where X > 1.
cBuffer(obj(O, _, _), 3).
"""


@pytest.fixture(scope="module")
def prepared_store(tmp_path_factory) -> Path:
    """The store of ``store``, made once for the module by ``slr load`` and ``slr add``."""
    folder = tmp_path_factory.mktemp("inspect")
    db = str(folder / "robot.db")
    (folder / "tea.slr").write_text(PROGRAM, encoding="utf-8")
    (folder / "other.slr").write_text("p(1).\n", encoding="utf-8")
    assert slr("load", db, str(folder / "tea.slr"), "--name", "tea").returncode == 0
    assert slr("load", db, str(folder / "other.slr")).returncode == 0
    r = slr("add", db, "obj(a, cup, [1, 2])^1", "obj(b, cup, red)^4",
            "seen(3)^[1700000000, 1700000002.5]")
    assert r.returncode == 0, r.stderr
    return Path(db)


@pytest.fixture
def store(tmp_path, prepared_store) -> str:
    """Two named programs and three events: the test's own copy of ``prepared_store``."""
    return copy_of_store(prepared_store, tmp_path)


def test_programs_lists_each_named_program_with_its_file(store):
    r = slr("programs", store)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert [line.split(":")[0] for line in lines] == ["tea", "main"]
    assert "1 text from " in lines[0] and "tea.slr" in lines[0] and "other.slr" in lines[1]
    assert re.search(r"loaded \d+\.\d\d \(\d{4}-\d\d-\d\d \d\d:\d\d:\d\d\.\d{3} UTC\)", lines[0])


def test_programs_source_prints_the_text(store):
    r = slr("programs", store, "--source")
    assert "    near(O) :- obj(O, _, _)^_." in r.stdout.splitlines()


def test_unload_removes_a_program_and_its_buffers_but_keeps_the_events(store):
    r = slr("unload", store, "tea")
    assert (r.returncode, r.stdout) == (0, "unloaded program tea\n")
    assert [line.split(":")[0] for line in slr("programs", store).stdout.splitlines()] == ["main"]
    assert "buffers" not in slr("describe", store, "obj").stdout
    assert slr("query", store, "obj(O, _, _)^T", "--json").stdout.count("\n") == 2
    again = slr("unload", store, "tea")
    assert again.returncode == 1
    assert again.stderr == "error: no program named 'tea' (loaded: 'main')\n"


def test_describe_says_count_times_sample_rules_and_buffers(store):
    r = slr("describe", store)
    assert r.returncode == 0, r.stderr
    blocks = {block.splitlines()[0].split()[0]: block
              for block in re.split(r"\n(?=\S)", r.stdout.strip())}
    assert sorted(blocks) == ["big/1", "obj/3", "seen/1"]
    obj = blocks["obj/3"].splitlines()
    assert obj[1:] == ["  events:      2",
                       "  end times:   1 .. 4",
                       "  sample:      obj(a,cup,[1,2])^1.0",
                       "  rules:       color/2^",
                       "               near/1",
                       "  buffers:     cBuffer(obj(O,_,_), 3)"]
    assert "event rules: big(X) <- seen(X)^T where X>1" in blocks["big/1"]
    assert "event rules: big(X) <- seen(X)^T where X>1" in blocks["seen/1"]


def test_describe_prints_epoch_times_readably(store):
    r = slr("describe", store, "seen/1")
    moment = datetime.datetime.fromtimestamp(1700000002.5, tz=datetime.UTC)
    assert (f"  end times:   1700000002.50 ({moment:%Y-%m-%d %H:%M:%S}.500 UTC) .. "
            in r.stdout)
    assert "sample:      seen(3)^[1700000000.0,1700000002.5]" in r.stdout


def test_describe_of_an_unknown_type_names_the_known_ones(store):
    r = slr("describe", store, "seg")
    assert r.returncode == 1
    assert r.stderr == "error: no event type seg in the store (known: big/1, obj/3, seen/1)\n"


@pytest.mark.parametrize("spec", ["a/b", "a/b/1"])
def test_describe_chooses_a_type_whose_name_holds_a_slash(tmp_path, spec):
    db = str(tmp_path / "robot.db")
    assert slr("add", db, "'a/b'(1)^1", "a(2)^2").returncode == 0
    r = slr("describe", db, spec)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[0].startswith("a/b/1  (table ") and "a/1 " not in r.stdout


@pytest.mark.parametrize("command", [["programs"], ["unload", "tea"], ["describe"]])
def test_reading_commands_need_an_existing_store(tmp_path, command):
    missing = str(tmp_path / "missing.db")
    r = slr(command[0], missing, *command[1:])
    assert (r.returncode, r.stderr) == (1, f"error: no such store: {missing}\n")
    assert not (tmp_path / "missing.db").exists()
