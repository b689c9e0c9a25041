"""The shared rule for tests that need something this machine may lack (tests/portable.py)."""

import pytest

from portable import in_ci, skip_or_fail


@pytest.mark.parametrize("value, expected", [("true", True), ("TRUE", True), ("1", True), ("yes", True),
                                             ("false", False), ("0", False), ("", False)])
def test_ci_is_read_from_the_environment(monkeypatch, value, expected):
    monkeypatch.setenv("CI", value)
    assert in_ci() is expected


def test_without_ci_a_missing_requirement_skips_with_its_reason(monkeypatch):
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match="no Chromium: apt-get install chromium"):
        skip_or_fail("no Chromium: apt-get install chromium")


def test_under_ci_the_same_requirement_fails(monkeypatch):
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="no Chromium: apt-get install chromium.*CI=true"):
        skip_or_fail("no Chromium: apt-get install chromium")
