"""Shared fixtures: the reference data in ../shared/data (beside the repository in CI)."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("CREEP_ONLINE_SHARED_DATA", REPO.parent / "shared" / "data"))


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path of ../shared/data; a missing folder is an error, not a skip: the references are the tests."""
    if not (SHARED_DATA / "fomcon" / "cases.json").exists():
        pytest.fail(f"reference data not found at {SHARED_DATA}; set CREEP_ONLINE_SHARED_DATA")
    return SHARED_DATA
