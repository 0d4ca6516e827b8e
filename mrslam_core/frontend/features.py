"""Keypoint detection (Harris, ORB, SIFT) and description (U-SURF, ORB, SIFT) as arrays.

All descriptors come out as UNIT-length float32 vectors so that the squared Euclidean distance of
000 eq. 16 lies in [0, 4] for every type (``descriptor_distance``); binary ORB strings become ±1/16
per bit, which makes that distance 4 × (Hamming distance / 256).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from mrslam_core.frontend.config import FrontendConfig
from mrslam_core.frontend.spread import select_spread
from mrslam_core.frontend.usurf import usurf

DESCRIPTOR_DIM = {"usurf": 64, "orb": 256, "sift": 128}
_SIFT_SIZE_PER_SCALE = 10.0
_CANDIDATES = 2  # OpenCV detections per kept keypoint, for the spread to choose from  # SIFT keypoint diameter given to scale-less (Harris) keypoints, per s


@dataclass(frozen=True)
class Keypoints:
    """Detections in one image.

    Attributes:
        xy: (N, 2) float (column, row) [px], pixel centres at integers.
        response: (N,) detector strength (larger is stronger; units depend on the detector).
        size: (N,) keypoint diameter [px] (0 for Harris).
        octave: (N,) OpenCV's packed octave of the detection (the pyramid level its descriptor is
            computed at), or None: 0 for all (Harris).
    """

    xy: np.ndarray
    response: np.ndarray
    size: np.ndarray
    octave: np.ndarray | None = None

    def __len__(self) -> int:
        return self.xy.shape[0]

    def take(self, index: np.ndarray) -> Keypoints:
        """Subset by index or boolean mask."""
        octave = None if self.octave is None else self.octave[index]
        return Keypoints(self.xy[index], self.response[index], self.size[index], octave)


def harris(image: np.ndarray, cfg: FrontendConfig, margin: int) -> Keypoints:
    """Harris corners: response map, non-maximum suppression, relative threshold (of the image's
    strongest), at most ``max_features`` spread over
    the ``grid_cols`` x ``grid_rows`` grid (each cell's strongest first, round-robin), strongest
    first.

    Args:
        image: (H, W) uint8.
        cfg: block size, k, quality, grid, NMS radius and max_features are used.
        margin: corners closer than this to the border are dropped [px].
    """
    resp = cv2.cornerHarris(image, cfg.harris_block_size, 3, cfg.harris_k)
    side = 2 * cfg.nms_radius + 1
    peak = resp >= cv2.dilate(resp, np.ones((side, side), np.uint8))
    top = max(float(resp.max()), 1e-12)
    peak &= resp > cfg.harris_quality * top
    peak[:margin] = False
    peak[-margin:] = False
    peak[:, :margin] = False
    peak[:, -margin:] = False
    rows, cols = np.nonzero(peak)
    strength = resp[rows, cols]
    if strength.size > cfg.max_features:
        keep = select_spread(np.stack([cols, rows], axis=1), strength, np.ones(strength.size, bool),
                             cfg.max_features, image.shape[1], image.shape[0], cfg.grid_cols, cfg.grid_rows)
        rows, cols, strength = rows[keep], cols[keep], strength[keep]
    order = np.argsort(-strength, kind="stable")
    xy = np.stack([cols[order], rows[order]], axis=1).astype(float)
    return Keypoints(xy, strength[order].astype(float), np.zeros(order.size))


def _from_cv(kps: list, image_shape: tuple[int, int], margin: int) -> Keypoints:
    if not kps:
        return Keypoints(np.zeros((0, 2)), np.zeros(0), np.zeros(0))
    xy = np.array([k.pt for k in kps], dtype=float)
    resp = np.array([k.response for k in kps], dtype=float)
    size = np.array([k.size for k in kps], dtype=float)
    octave = np.array([k.octave for k in kps], dtype=np.int64)
    h, w = image_shape
    c = np.rint(xy)
    ok = (c[:, 0] >= margin) & (c[:, 0] < w - margin) & (c[:, 1] >= margin) & (c[:, 1] < h - margin)
    order = np.flatnonzero(ok)[np.argsort(-resp[ok], kind="stable")]
    # one keypoint per pixel, the strongest: SIFT gives one per orientation of a blob, and the
    # descriptors here are upright, so they would be copies of each other that no ratio test
    # can tell apart
    _, first = np.unique(c[order], axis=0, return_index=True)
    order = order[np.sort(first)]
    return Keypoints(xy[order], resp[order], size[order], octave[order])


class FeatureExtractor:
    """Detector and descriptor picked by the config; OpenCV objects made once.

    Args:
        cfg: frontend config (detector, descriptor, max_features, usurf_scale, Harris settings).
    """

    def __init__(self, cfg: FrontendConfig):
        self.cfg = cfg
        self.dim = DESCRIPTOR_DIM[cfg.descriptor]
        # the OpenCV detectors find more than max_features, and the spread picks among them
        self._orb = cv2.ORB_create(nfeatures=_CANDIDATES * cfg.max_features, nlevels=cfg.orb_levels,
                                   edgeThreshold=15, patchSize=31)
        self._sift = cv2.SIFT_create(nfeatures=_CANDIDATES * cfg.max_features)

    def detect(self, image: np.ndarray, margin: int) -> Keypoints:
        """Keypoints of a grey (H, W) uint8 image, strongest first, at most max_features spread
        over the image grid."""
        if self.cfg.detector == "harris":
            return harris(image, self.cfg, margin)
        det = self._orb if self.cfg.detector == "orb" else self._sift
        kps = _from_cv(list(det.detect(image, None)), image.shape, margin)
        c = self.cfg
        pick = select_spread(kps.xy, kps.response, np.ones(len(kps), bool), c.max_features,
                             image.shape[1], image.shape[0], c.grid_cols, c.grid_rows)
        return kps.take(np.sort(pick))  # _from_cv ordered them strongest first

    def describe(self, image: np.ndarray, kps: Keypoints) -> tuple[np.ndarray, np.ndarray]:
        """Unit float32 descriptors (N, D) and a (N,) mask of keypoints that got one.

        U-SURF always uses the fixed scale ``usurf_scale``; ORB/SIFT descriptors of keypoints of
        another detector use a fixed size (ORB's 31 px patch; SIFT 10·usurf_scale). Keypoints that
        a descriptor cannot serve (ORB near the border) get zeros and False.
        """
        n = len(kps)
        out = np.zeros((n, self.dim), np.float32)
        if n == 0:
            return out, np.zeros(0, bool)
        if self.cfg.descriptor == "usurf":
            out = usurf(image, kps.xy, self.cfg.usurf_scale)
            return out, np.ones(n, bool)
        octave = np.zeros(n, np.int64)
        if self.cfg.descriptor == self.cfg.detector:
            size = kps.size  # the detector's own scale and pyramid level
            octave = kps.octave if kps.octave is not None else octave
        elif self.cfg.descriptor == "orb":
            size = np.full(n, 31.0)
        else:  # SIFT windows of a fixed scale for keypoints of another detector
            size = np.full(n, _SIFT_SIZE_PER_SCALE * self.cfg.usurf_scale)
        cv_kps = [
            cv2.KeyPoint(float(x), float(y), float(s), 0.0, 0.0, int(o), int(i))
            for i, ((x, y), s, o) in enumerate(zip(kps.xy, size, octave))
        ]
        ext = self._orb if self.cfg.descriptor == "orb" else self._sift
        got, desc = ext.compute(image, cv_kps)
        ok = np.zeros(n, bool)
        if desc is None or not got:
            return out, ok
        idx = np.array([k.class_id for k in got], dtype=np.int64)
        if self.cfg.descriptor == "orb":
            bits = np.unpackbits(desc, axis=1).astype(np.float32)
            vec = (2.0 * bits - 1.0) / np.sqrt(bits.shape[1])
        else:
            vec = desc.astype(np.float32)
            vec /= np.maximum(np.linalg.norm(vec, axis=1, keepdims=True), 1e-12)
        out[idx] = vec
        ok[idx] = True
        return out, ok


def descriptor_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Squared Euclidean distances (000 eq. 16) between unit descriptors a (N, D), b (M, D) -> (N, M).

    Computed as 2 − 2·a·bᵀ (exact for unit vectors), clipped to [0, 4].
    """
    a = np.asarray(a, np.float32)
    b = np.asarray(b, np.float32)
    return np.clip(2.0 - 2.0 * (a @ b.T), 0.0, 4.0)
