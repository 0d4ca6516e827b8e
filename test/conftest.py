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


@pytest.fixture(scope="session")
def kitti_dir(shared_data: Path) -> Path:
    """The KITTI odometry excerpt (51 rectified stereo pairs, calib.txt, poses.txt)."""
    folder = shared_data / "kitti_excerpt"
    if not (folder / "calib.txt").is_file():
        pytest.skip(f"KITTI excerpt not found at {folder}")
    return folder


@pytest.fixture(scope="session")
def euroc_micro(shared_data: Path) -> Path:
    """The 30 still EuRoC V1_01 stereo pairs with both cameras' sensor.yaml."""
    folder = shared_data / "euroc_v101_micro"
    if not (folder / "cam0" / "sensor.yaml").is_file():
        pytest.skip(f"EuRoC micro sample not found at {folder}")
    return folder


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Modules that hold a slow test run first, each module's tests in their own order.

    `make test` hands whole modules to its two workers (``--dist loadfile
    --no-loadscope-reorder``). xdist's default order, modules with the most tests first, handed the
    real-data and world-gate modules (one to six tests of 1-5 min each) out last, and one worker
    ran them while the other had finished: longest first is what balances the two."""
    slow = {item.path for item in items if item.get_closest_marker("slow") is not None}
    items.sort(key=lambda item: item.path not in slow)
