"""Test-wide settings: no test reads or writes the user's own app data (their stride profile)."""

import pytest


@pytest.fixture(autouse=True)
def _isolated_app_data(tmp_path_factory, monkeypatch):
    """``PDR_APP_DATA`` points at an empty folder, so ``pdr replay`` never finds a real ``profile.json``
    (subprocesses inherit it); tests that need one set their own."""
    monkeypatch.setenv("PDR_APP_DATA", str(tmp_path_factory.mktemp("app-data")))
