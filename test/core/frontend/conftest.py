"""Shared fixtures of the frontend tests: the real-data folder and small synthetic rigs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mrslam_core.frontend import StereoRig

DATA = Path(__file__).resolve().parents[3].parent / "shared" / "data"
EUROC = DATA / "euroc_v101_micro"

# base_link (x forward, y left, z up) <- camera optical (x right, y down, z forward), camera 0.5 m up
# and 0.1 m ahead of the base origin
T_BASE_CAM = np.array([
    [0.0, 0.0, 1.0, 0.1],
    [-1.0, 0.0, 0.0, 0.0],
    [0.0, -1.0, 0.0, 0.5],
    [0.0, 0.0, 0.0, 1.0],
])


@pytest.fixture
def euroc_dir() -> Path:
    if not (EUROC / "cam0" / "sensor.yaml").is_file():
        pytest.skip(f"real data absent: {EUROC} (the shared data folder beside the repository)")
    return EUROC


@pytest.fixture
def small_rig() -> StereoRig:
    """320 x 240 rectified rig, f = 300 px, baseline 0.12 m."""
    return StereoRig.rectified(320, 240, 300.0, 160.0, 120.0, 0.12, T_BASE_CAM)


def _textured(height: int, width: int, seed: int) -> np.ndarray:
    import cv2

    rng = np.random.default_rng(seed)
    img = rng.uniform(0, 255, (height // 4 + 1, width // 4 + 1)).astype(np.float32)
    img = cv2.resize(img, (width + 8, height + 8), interpolation=cv2.INTER_CUBIC)[4:-4, 4:-4]
    img = cv2.GaussianBlur(img, (0, 0), 1.0)
    img = (img - img.min()) / (img.max() - img.min()) * 235 + 10
    return img.astype(np.uint8)


@pytest.fixture
def textured():
    """Maker of smooth random textures (H, W) uint8 with many corners: f(height, width, seed)."""
    return _textured
