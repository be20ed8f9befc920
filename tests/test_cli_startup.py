"""What `slr` imports before it runs a command: every command pays it (the suite starts `slr`
hundreds of times), so the modules of optional extras and of other commands wait until used."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from click.testing import CliRunner

ROOT = Path(__file__).resolve().parent.parent

# Imported only by the commands that use them (an extra's missing package is reported by the
# command that needs it, in words): none of them on `import slr_sql.cli`.
NOT_ON_IMPORT = (
    "psycopg", "httpx", "certifi", "rclpy", "rosbags", "yaml", "mcap", "uvicorn", "starlette",
    "rich", "prompt_toolkit", "matplotlib", "sqlite_utils", "socket",
    "slr_sql.service.app", "slr_sql.service.client", "slr_sql.service.cli", "slr_sql.fleet",
    "slr_sql.ros.cli", "slr_sql.viz.cli", "slr_sql.plot", "slr_sql.demo",
    "slr_sql.grammar.slr_parser",   # (the parser's tables: imported by the first parse)
    "slr_sql.store.postgres",       # (by the first store opened on a postgresql:// URL)
)


def test_importing_the_cli_imports_no_extra_and_no_other_commands_module():
    # A fresh interpreter: what this test process imported already would hide an import.
    # (The sandbox's own site hooks may import certifi before any code runs: only the
    # modules the import adds count.)
    code = ("import json, sys; before = set(sys.modules); import slr_sql.cli; "
            "print(json.dumps(sorted(set(sys.modules) - before)))")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT, env=env, timeout=60)
    assert done.returncode == 0, done.stderr
    imported = set(json.loads(done.stdout))
    assert "slr_sql.kb" in imported   # (the check sees the package's imports)
    assert sorted(name for name in imported
                  if name.split(".")[0] in NOT_ON_IMPORT or name in NOT_ON_IMPORT) == []



def test_writing_ascii_terms_compiles_none_of_the_unicode_classes():
    # The writer's regexes of every script's letters and symbols take ~25 ms to compile: a
    # command that writes ASCII (all most commands write) compiles none of them; the first
    # non-ASCII atom compiles what it needs, and is written as SWI-Prolog writes it.
    code = ("import json, re; compiled = []; real = re.compile; "
            "re.compile = lambda p, f=0: compiled.append(len(str(p))) or real(p, f); "
            "import slr_sql.cli; from slr_sql.terms import format_term, Struct, Atom; "
            "ascii = format_term(Struct('f', (Atom('cup1'), Atom('a b'), Atom('=..'), "
            "Atom('it\\'s'), Atom('tab\\t')))); before = max(compiled); "
            "other = format_term(Struct('f', (Atom('\u00e9t\u00e9'), Atom('\u2192'), "
            "Atom('\u00c9mile'), Atom('a\u2028b')))); "
            "print(json.dumps([ascii, before, other, max(compiled)]))")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT, env=env, timeout=60)
    assert done.returncode == 0, done.stderr
    ascii, before, other, longest = json.loads(done.stdout)
    assert ascii == "f(cup1,'a b',=..,'it\\'s','tab\\t')"
    assert before < 2000                  # (no class compiled on import or writing ASCII)
    assert other == "f(\u00e9t\u00e9,\u2192,'\u00c9mile','a\\x2028\\b')"
    assert longest > 4000                 # (the first non-ASCII atom compiled the classes)


def test_the_commands_imported_on_use_list_run_and_are_suggested_like_the_others():
    from slr_sql.cli import LAZY_COMMANDS, main

    runner = CliRunner()
    listed = runner.invoke(main, ["--help"], terminal_width=200)
    assert listed.exit_code == 0
    rows = listed.output.split("Commands:")[1]
    for name in LAZY_COMMANDS:
        assert f"\n  {name} " in rows
    # A group loaded on use lists its subcommands with their first sentence whole, as the
    # group on the top level does (click would cut them at 45 characters, with "...").
    fleet = runner.invoke(main, ["fleet", "--help"], terminal_width=80)
    assert fleet.exit_code == 0
    subcommands = " ".join(fleet.output.split("Commands:")[1].split())
    assert "Name the robot the store DB belongs to (kept in the store; once for life)." \
        in subcommands and "..." not in subcommands

    # click's "Did you mean" picks from every command, the ones not loaded yet too (a fresh
    # process: in this one, --help above loaded them all)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    wrong = subprocess.run([sys.executable, "-m", "slr_sql", "serv"], capture_output=True,
                           text=True, cwd=ROOT, env=env, timeout=60)
    assert wrong.returncode == 2 and "No such command 'serv'" in wrong.stderr
    if "Did you mean" in wrong.stderr:   # (click >= 8.2 suggests)
        assert "'serve'" in wrong.stderr
