"""Build of the optional C accelerator; everything else is in pyproject.toml.

``_slr_sql_speedups`` (csrc/) speeds up the column encoder's two hottest loops. It is
optional: without a C compiler the build skips it and slr_sql encodes the same text in Python.
It is a top-level module (not ``slr_sql._speedups``) so that a source checkout on
``sys.path`` (``python -m pytest`` in the repository) still finds the installed build.
"""
from setuptools import Extension, setup

setup(ext_modules=[Extension("_slr_sql_speedups", ["csrc/_slr_sql_speedups.c"],
                             optional=True)])
