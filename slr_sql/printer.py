"""Transitional alias: term printing lives in :mod:`slr_sql.terms` (``format_term``)."""
from .terms import INFIX_OPS, OPERATORS, PREFIX_OPS, format_atom, format_term  # noqa: F401

__all__ = ["format_term", "format_atom", "INFIX_OPS", "PREFIX_OPS", "OPERATORS"]
