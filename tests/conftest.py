"""Shared fixtures: the reference data the tests need lives in tests/data (each folder with its source and licence)."""
from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DATA = Path(__file__).resolve().parent / "data"


@pytest.fixture(scope="session")
def reference_data() -> Path:
    """Path of tests/data: FOMCON outputs, exact references and real measurements."""
    return DATA
