"""Upright SURF (U-SURF) descriptors from integral images, vectorised over keypoints.

Bay, Tuytelaars, Van Gool, *SURF: Speeded Up Robust Features*, ECCV 2006, section 4: around a
keypoint of scale s, a square window of side 20s is split into 4 × 4 subregions; in each, Haar
wavelet responses of size 2s in x and y are taken at 5 × 5 regularly spaced sample points (spacing
s), weighted by a Gaussian of σ = 3.3s centred at the keypoint, and summed as
(Σdx, Σ|dx|, Σdy, Σ|dy|). The 64 values are normalised to unit length. "Upright": no orientation
assignment, the window stays aligned with the image axes (robots' cameras do not roll).

The Haar responses are box-filter differences evaluated on an integral image for the whole image
at once (9 shifted slices of the integral image), then gathered at every keypoint's 20 × 20 sample
grid; all keypoints share one scale, as with Harris corners.
"""

from __future__ import annotations

import cv2
import numpy as np

DIM = 64


def haar_responses(image: np.ndarray, half: int) -> tuple[np.ndarray, np.ndarray]:
    """Dense Haar wavelet responses centred on every pixel, from one integral image.

    The wavelet is (2·half + 1) pixels square, centred on the pixel: dx = sum of the ``half``
    columns right of it minus the ``half`` columns left of it (over all 2·half + 1 rows); dy the
    same downwards minus upwards. Odd, pixel-centred wavelets at a sample spacing of up to
    2·half + 1 px leave no image edge unseen.

    Args:
        image: (H, W) uint8 grey image (reflected at the border).
        half: half the wavelet side [px] (>= 1).

    Returns:
        (dx, dy): (H, W) float32, positive where the image gets brighter rightwards / downwards.
    """
    h, w = image.shape
    p = half
    padded = cv2.copyMakeBorder(image, p, p, p, p, cv2.BORDER_REFLECT_101)
    integ = cv2.integral(padded, sdepth=cv2.CV_32S)  # exact in int32 for 8-bit images

    def box(r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
        # sum over rows [v + r0, v + r1) and columns [u + c0, u + c1) for every pixel (u, v)
        def at(r: int, c: int) -> np.ndarray:
            return integ[p + r: p + r + h, p + c: p + c + w]
        return at(r1, c1) - at(r0, c1) - at(r1, c0) + at(r0, c0)

    dx = box(-half, half + 1, 1, half + 1) - box(-half, half + 1, -half, 0)
    dy = box(1, half + 1, -half, half + 1) - box(-half, 0, -half, half + 1)
    return dx.astype(np.float32), dy.astype(np.float32)


def usurf(image: np.ndarray, xy: np.ndarray, scale: float) -> np.ndarray:
    """U-SURF descriptors of keypoints at one scale.

    Args:
        image: (H, W) uint8 grey image.
        xy: (N, 2) keypoint (column, row) [px]; rounded to the nearest pixel.
        scale: SURF scale s [px] (window 20s, wavelet 2s, sample spacing s).

    Returns:
        (N, 64) float32 unit-length descriptors, ordered per subregion (row-major over 4 × 4) as
        (Σdx, Σ|dx|, Σdy, Σ|dy|); all-zero for a perfectly flat window.
    """
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    n = xy.shape[0]
    if n == 0:
        return np.zeros((0, DIM), np.float32)
    half = max(1, int(round(scale)))
    dx, dy = haar_responses(image, half)
    offs = np.rint((np.arange(20) - 9.5) * scale).astype(np.int64)
    g = np.exp(-((np.arange(20) - 9.5) * scale) ** 2 / (2 * (3.3 * scale) ** 2))
    weight = (g[:, None] * g[None, :]).astype(np.float32)  # (20 rows, 20 cols)
    h, w = dx.shape
    u = np.rint(xy[:, 0]).astype(np.int64)[:, None, None] + offs[None, None, :]
    v = np.rint(xy[:, 1]).astype(np.int64)[:, None, None] + offs[None, :, None]
    u = np.clip(u, 0, w - 1)
    v = np.clip(v, 0, h - 1)
    idx = v * w + u  # (N, 20, 20)
    sx = dx.ravel()[idx] * weight
    sy = dy.ravel()[idx] * weight
    # (N, 4 subregion rows, 5, 4 subregion cols, 5) -> sums per subregion
    parts = np.stack([sx, np.abs(sx), sy, np.abs(sy)], axis=-1).reshape(n, 4, 5, 4, 5, 4)
    desc = parts.sum(axis=(2, 4)).reshape(n, DIM)
    norm = np.linalg.norm(desc, axis=1, keepdims=True)
    return (desc / np.where(norm > 0, norm, 1.0)).astype(np.float32)
