"""The suite guards itself: a hung test fails (pytest-timeout, configured in pyproject.toml)
instead of blocking the run."""
from __future__ import annotations


def test_a_hanging_test_fails_after_the_configured_timeout(request):
    assert request.config.pluginmanager.hasplugin("timeout"), "pytest-timeout is not active"
    timeout = float(request.config.getini("timeout"))
    assert 60 <= timeout <= 600, timeout
