"""Every docstring example in the package runs as written (public functions carry one: it
must stay true as the code changes)."""
from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import slr_sql

MODULES = sorted(info.name for info in pkgutil.walk_packages(slr_sql.__path__, "slr_sql.")
                 if info.name != "slr_sql.__main__")


@pytest.mark.parametrize("name", MODULES)
def test_the_examples_of_each_module_run(name):
    module = importlib.import_module(name)
    failures, _tried = doctest.testmod(module, verbose=False,
                                       optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert failures == 0, f"{name}: {failures} docstring example(s) failed (run "\
        f"python -m pytest --doctest-modules {name.replace('.', '/')}.py to see them)"


def test_every_module_is_checked():
    assert "slr_sql.encoding" in MODULES and "slr_sql.store.connection" in MODULES
    assert len(MODULES) > 40


def test_examples_are_valid_python_without_escape_warnings():
    r"""A docstring that is not raw turns ``"\\="`` into ``"\="``, which Python reads with a
    warning (an error in a later Python): every example must compile cleanly."""
    import warnings

    finder = doctest.DocTestFinder()
    bad = []
    for name in MODULES:
        for test in finder.find(importlib.import_module(name)):
            for example in test.examples:
                with warnings.catch_warnings():
                    warnings.simplefilter("error")
                    try:
                        compile(example.source, f"<{test.name}>", "single")
                    except (SyntaxError, DeprecationWarning, SyntaxWarning) as exc:
                        if "escape" in str(exc):
                            bad.append(f"{test.name}: {example.source.strip()} ({exc})")
    assert not bad, "\n".join(bad)
