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


def test_every_public_function_and_method_of_the_api_has_an_example():
    """The package's functions and the knowledge base's methods each show one runnable
    example (run by the test above), so a reader sees a call that works."""
    import inspect

    from slr_sql.kb import KnowledgeBase

    public = {name: getattr(slr_sql, name) for name in slr_sql.__all__
              if inspect.isfunction(getattr(slr_sql, name))}
    public.update({f"KnowledgeBase.{name}": member for name, member in vars(KnowledgeBase).items()
                   if not name.startswith("_") and inspect.isfunction(member)})
    assert len(public) > 20
    without = sorted(name for name, member in public.items() if ">>>" not in (member.__doc__ or ""))
    assert without == []
