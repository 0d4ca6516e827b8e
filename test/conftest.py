"""Shared fixtures: where ../shared/data is, and a skip when it is absent."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The project's real data folder (../shared/data beside the repository)."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data not found at {SHARED_DATA} (clone the repo beside ../shared)")
    return SHARED_DATA


@pytest.fixture(scope="session")
def mrclam6(shared_data: Path) -> Path:
    folder = shared_data / "mrclam" / "dataset6"
    if not folder.is_dir():
        pytest.skip(f"MR.CLAM dataset 6 not found at {folder}")
    return folder
