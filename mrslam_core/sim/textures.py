"""Procedural textures rich in corners, deterministic from a seed (PNG files for pybullet)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np


def unique_texture(size: int, seed: int) -> np.ndarray:
    """(size, size, 3) uint8: random rectangles, discs and strokes over noise — no two alike."""
    rng = np.random.default_rng(seed)
    img = rng.integers(90, 170, (size // 8, size // 8), dtype=np.uint8)
    img = cv2.resize(img, (size, size), interpolation=cv2.INTER_CUBIC)
    for _ in range(int(rng.integers(60, 90))):
        shade = int(rng.integers(0, 256))
        kind = rng.integers(0, 3)
        p = rng.integers(0, size, 2)
        if kind == 0:
            q = p + rng.integers(size // 30, size // 6, 2)
            cv2.rectangle(img, (int(p[0]), int(p[1])), (int(q[0]), int(q[1])), shade, -1)
        elif kind == 1:
            cv2.circle(img, (int(p[0]), int(p[1])), int(rng.integers(size // 40, size // 10)), shade, -1)
        else:
            q = rng.integers(0, size, 2)
            cv2.line(img, (int(p[0]), int(p[1])), (int(q[0]), int(q[1])), shade, int(rng.integers(2, 6)))
    img = cv2.GaussianBlur(img, (0, 0), size / 256)  # band-limit: the renderer samples without filtering
    return np.repeat(img[..., None], 3, axis=2)


def repetitive_texture(size: int, tiles: int = 8) -> np.ndarray:
    """(size, size, 3) uint8 checkerboard with a small mark in every tile: many look-alike corners."""
    t = size // tiles
    yy, xx = np.mgrid[0:size, 0:size]
    img = np.where(((yy // t) + (xx // t)) % 2 == 0, 60, 200).astype(np.uint8)
    img[(yy % t > t // 3) & (yy % t < t // 2) & (xx % t > t // 3) & (xx % t < t // 2)] = 130
    img = cv2.GaussianBlur(img, (0, 0), size / 256)
    return np.repeat(img[..., None], 3, axis=2)


def write_texture(img: np.ndarray, folder: Path, name: str) -> Path:
    """Save as PNG (pybullet loads textures from files) and return the path."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.png"
    if not path.exists():
        cv2.imwrite(str(path), img)
    return path
