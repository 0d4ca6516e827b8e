"""Procedural textures, deterministic from a random generator.

Sizes are given in texels; ``density`` [texels/m] sets the physical scale of the drawn shapes,
so a texture looks the same whatever surface it covers. Images are (H, W, 3) uint8 RGB.
"""

from __future__ import annotations

import cv2
import numpy as np


def unique_texture(height: int, width: int, rng: np.random.Generator, density: float) -> np.ndarray:
    """Shapes rich in corners over a smooth background, about 40 per square metre.

    Rectangles, rotated quadrilaterals, triangles, discs, strokes and small "posters" (grids of
    tiles) of 3–40 cm, in random colours with strong contrast; no two textures alike.
    """
    if height < 1 or width < 1:
        raise ValueError("texture size must be positive")
    small = rng.uniform(70, 190, (max(2, height // 24), max(2, width // 24), 3)).astype(np.float32)
    img = cv2.resize(small, (width, height), interpolation=cv2.INTER_CUBIC)
    img = np.clip(img, 0, 255).astype(np.uint8)
    area = height * width / density ** 2
    n = int(rng.poisson(40 * area)) + 3
    kinds = rng.integers(0, 6, n)
    centres = rng.uniform([0, 0], [width, height], (n, 2))
    sizes = rng.uniform(0.03, 0.4, n) * density
    colours = rng.integers(0, 256, (n, 3))
    grey = rng.random(n) < 0.5
    colours[grey] = colours[grey, :1]
    for kind, (cx, cy), s, col in zip(kinds, centres, sizes, colours):
        c = tuple(int(v) for v in col)
        if kind == 0:
            w, h = s * rng.uniform(0.3, 1.0, 2)
            cv2.rectangle(img, (int(cx - w / 2), int(cy - h / 2)), (int(cx + w / 2), int(cy + h / 2)), c, -1)
        elif kind == 1:
            ang = rng.uniform(0, np.pi)
            w, h = s * rng.uniform(0.3, 1.0, 2) / 2
            u, v = np.array([np.cos(ang), np.sin(ang)]), np.array([-np.sin(ang), np.cos(ang)])
            quad = np.array([[cx, cy]]) + np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]]) @ np.stack([w * u, h * v])
            cv2.fillPoly(img, [np.round(quad).astype(np.int32)], c)
        elif kind == 2:
            tri = np.array([[cx, cy]]) + rng.uniform(-s / 2, s / 2, (3, 2))
            cv2.fillPoly(img, [np.round(tri).astype(np.int32)], c)
        elif kind == 3:
            cv2.circle(img, (int(cx), int(cy)), max(1, int(s / 3)), c, -1)
        elif kind == 4:
            d = rng.uniform(-s, s, 2)
            cv2.line(img, (int(cx), int(cy)), (int(cx + d[0]), int(cy + d[1])), c, max(1, int(s / 12)))
        else:
            cells = int(rng.integers(2, 5))
            step = max(2, int(s / cells))
            x0, y0 = int(cx - s / 2), int(cy - s / 2)
            cv2.rectangle(img, (x0, y0), (x0 + cells * step, y0 + cells * step), c, -1)
            for i in range(cells):
                for j in range(cells):
                    if rng.random() < 0.5:
                        cv2.rectangle(img, (x0 + i * step + 1, y0 + j * step + 1),
                                      (x0 + (i + 1) * step - 2, y0 + (j + 1) * step - 2),
                                      tuple(int(255 - v) for v in col), -1)
    # band-limit: TinyRenderer samples the nearest texel without filtering
    return cv2.GaussianBlur(img, (0, 0), 0.6)


def repetitive_texture(height: int, width: int, density: float, period: float = 0.25) -> np.ndarray:
    """A checkerboard of ``period`` [m] squares with the same small mark in every square:
    many look-alike corners, the hard case for data association."""
    t = max(4, int(round(period * density)))
    yy, xx = np.mgrid[0:height, 0:width]
    img = np.where(((yy // t) + (xx // t)) % 2 == 0, 60, 200).astype(np.uint8)
    mark = (yy % t > t // 4) & (yy % t < t // 2) & (xx % t > t // 4) & (xx % t < t // 2)
    img[mark] = 130
    return cv2.GaussianBlur(np.repeat(img[..., None], 3, axis=2), (0, 0), 0.6)


def plain_texture(height: int, width: int, shade: int = 200) -> np.ndarray:
    """A uniform surface without features (a painted wall)."""
    return np.full((height, width, 3), shade, np.uint8)
