"""The stereo frontend: one step per stereo pair, observations and an obstacle scan out.

Per pair (000 sections 3.2, 6.1): rectify, detect in the left image, match along the rectified
row, triangulate (eq. 12) with covariance R = J·Rsp·Jᵀ, describe, track over frames, and publish
the points tracked for ``min_track_length`` consecutive frames, at most B of them spread over the
image, in base_link (x forward, y left, z up).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import cv2
import numpy as np

from mrslam_core.frontend.camera import StereoRig
from mrslam_core.frontend.config import FrontendConfig
from mrslam_core.frontend.features import FeatureExtractor, Keypoints
from mrslam_core.frontend.matching import match_stereo
from mrslam_core.frontend.obstacles import ObstacleScan, ObstacleScanner
from mrslam_core.frontend.tracking import Tracker, select_spread
from mrslam_core.geometry.stereo import optical_to_body, triangulate, triangulation_covariance
from mrslam_core.types import ObservationSet

_ENCODINGS = {  # encoding -> (channels, dtype, conversion to grey)
    "mono8": (1, np.uint8, None),
    "8UC1": (1, np.uint8, None),
    "mono16": (1, np.uint16, None),
    "16UC1": (1, np.uint16, None),
    "bgr8": (3, np.uint8, cv2.COLOR_BGR2GRAY),
    "rgb8": (3, np.uint8, cv2.COLOR_RGB2GRAY),
    "bgra8": (4, np.uint8, cv2.COLOR_BGRA2GRAY),
    "rgba8": (4, np.uint8, cv2.COLOR_RGBA2GRAY),
}


@dataclass(frozen=True)
class StereoFrame:
    """Every stereo point of one frame (before the choice of B), in the rectified left camera.

    Attributes:
        xy: (M, 2) rectified left pixel (column, row) [px].
        disparity: (M,) [px].
        strength: (M,) detector response.
        points: (M, 3) left rectified optical frame (x right, y down, z forward) [m].
        cov: (M, 3, 3) [m²], same frame.
        descriptors: (M, D) unit float32.
        track_ids: (M,) int64.
        track_length: (M,) consecutive frames seen, this one included.
        detected: keypoints the detector found in the left image (before stereo matching).
        matched: of those, the ones stereo matching accepted (before the depth limits).
    """

    xy: np.ndarray
    disparity: np.ndarray
    strength: np.ndarray
    points: np.ndarray
    cov: np.ndarray
    descriptors: np.ndarray
    track_ids: np.ndarray
    track_length: np.ndarray
    detected: int = 0
    matched: int = 0


def image_to_grey(image: object, encoding: str | None) -> tuple[np.ndarray | None, str]:
    """A grey (H, W) uint8 image from an array and a ROS-style encoding, or (None, drop reason).

    Without an encoding, (H, W) uint8 is mono8, (H, W) uint16 mono16, (H, W, 3|4) uint8 bgr8/bgra8
    (OpenCV's order). 16-bit images keep their 8 most significant bits.
    """
    if not isinstance(image, np.ndarray):
        return None, "not_an_array"
    if image.size == 0:
        return None, "empty"
    if encoding is None:
        if image.ndim == 2 and image.dtype in (np.uint8, np.uint16):
            encoding = "mono8" if image.dtype == np.uint8 else "mono16"
        elif image.ndim == 3 and image.dtype == np.uint8 and image.shape[2] in (3, 4):
            encoding = "bgr8" if image.shape[2] == 3 else "bgra8"
        else:
            return None, "unsupported_dtype"
    if encoding not in _ENCODINGS:
        return None, "unsupported_encoding"
    channels, dtype, code = _ENCODINGS[encoding]
    shape_ok = image.ndim == 2 if channels == 1 else (image.ndim == 3 and image.shape[2] == channels)
    if not shape_ok or image.dtype != dtype:
        return None, "encoding_mismatch"
    if dtype == np.uint16:
        return (image >> 8).astype(np.uint8), encoding
    if code is not None:
        return cv2.cvtColor(image, code), encoding
    return np.ascontiguousarray(image), encoding


class Frontend:
    """Stereo visual frontend of one robot.

    Args:
        rig: calibrated stereo rig (raises :class:`CameraModelError` when built from bad info).
        cfg: frontend config.
        robot: robot name written into the observation sets.

    Attributes:
        drops: Counter of dropped pairs by reason (``empty``, ``size_mismatch``, ``saturated``,
            ``encoding_mismatch``, ``stamp_skew``, ``stamp_out_of_order``, ``internal_error``, ...).
        frames: pairs processed (not dropped).
        last_frame: the :class:`StereoFrame` of the last processed pair (for tools and tests).
        last_error: text of the last ``internal_error``.
    """

    def __init__(self, rig: StereoRig, cfg: FrontendConfig | None = None, robot: str = "robot1"):
        self.rig = rig
        self.cfg = cfg if cfg is not None else FrontendConfig()
        self.robot = robot
        self.features = FeatureExtractor(self.cfg)
        self.tracker = Tracker(self.cfg)
        self.scanner = ObstacleScanner(rig, self.cfg)
        self.drops: Counter[str] = Counter()
        self.frames = 0
        self.last_frame: StereoFrame | None = None
        self.last_error: str | None = None
        self._last_stamp: int | None = None
        self._margin = 2 * self.cfg.patch_radius + 1

    def reset(self) -> None:
        """Forget tracks (e.g. after a gap in the stream)."""
        self.tracker.reset()
        self._last_stamp = None

    def _drop(self, reason: str) -> tuple[None, None]:
        self.drops[reason] += 1
        return None, None

    def step(
        self, left: np.ndarray, right: np.ndarray, stamp_ns: int, *,
        right_stamp_ns: int | None = None, encoding: str | None = None,
        right_encoding: str | None = None,
    ) -> tuple[ObservationSet | None, ObstacleScan | None]:
        """Process one stereo pair. Never raises: bad input is dropped and counted in ``drops``.

        Args:
            left, right: raw images (H, W) or (H, W, C) of the calibrated size.
            stamp_ns: left image time (ns); the observations carry it.
            right_stamp_ns: right image time (ns), checked against ``max_stamp_skew_ns``.
            encoding, right_encoding: ROS image encodings (None: inferred from the array;
                right_encoding defaults to encoding).

        Returns:
            (observations in base_link, possibly empty; obstacle scan), or (None, None) for a drop.
        """
        try:
            return self._step(left, right, stamp_ns, right_stamp_ns, encoding,
                              right_encoding if right_encoding is not None else encoding)
        except Exception as exc:  # noqa: BLE001 - the frontend must keep running; counted below
            self.last_error = f"{type(exc).__name__}: {exc}"
            return self._drop("internal_error")

    def _step(self, left, right, stamp_ns, right_stamp_ns, encoding, right_encoding):
        cfg = self.cfg
        if isinstance(stamp_ns, bool) or not isinstance(stamp_ns, (int, np.integer)) or stamp_ns < 0:
            return self._drop("bad_stamp")
        stamp_ns = int(stamp_ns)
        if right_stamp_ns is not None and abs(int(right_stamp_ns) - stamp_ns) > cfg.max_stamp_skew_ns:
            return self._drop("stamp_skew")
        if self._last_stamp is not None and stamp_ns <= self._last_stamp:
            return self._drop("stamp_out_of_order")
        gl, enc_l = image_to_grey(left, encoding)
        if gl is None:
            return self._drop(enc_l)
        gr, enc_r = image_to_grey(right, right_encoding)
        if gr is None:
            return self._drop(enc_r)
        if enc_l != enc_r:
            return self._drop("encoding_mismatch")
        if gl.shape != gr.shape or gl.shape != (self.rig.height, self.rig.width):
            return self._drop("size_mismatch")
        n_pix = gl.size
        for g in (gl, gr):
            if n_pix - cv2.countNonZero(cv2.inRange(g, 1, 254)) > cfg.saturated_fraction * n_pix:
                return self._drop("saturated")
        gl, gr = self.rig.rectify(gl, gr)
        frame = self.process_rectified(gl, gr)
        self._last_stamp = stamp_ns
        self.frames += 1
        self.last_frame = frame
        eligible = frame.track_length >= cfg.min_track_length
        pick = select_spread(frame.xy, frame.strength, eligible, cfg.max_observations,
                             self.rig.width, self.rig.height, cfg.grid_cols, cfg.grid_rows)
        z, cov = optical_to_body(frame.points[pick], frame.cov[pick], self.rig.t_base_rect)
        obs = ObservationSet(self.robot, stamp_ns, z.reshape(-1, 3), cov.reshape(-1, 3, 3),
                             frame.descriptors[pick], frame.track_ids[pick])
        if cfg.obstacle_source == "dense":
            scan = self.scanner.from_images(gl, gr, stamp_ns)
        else:
            pts, _ = optical_to_body(frame.points, None, self.rig.t_base_rect)
            scan = self.scanner.from_points(pts, stamp_ns)
        return obs, scan

    def process_rectified(self, left: np.ndarray, right: np.ndarray) -> StereoFrame:
        """Detect, match, triangulate, describe and track on a rectified grey pair (H, W) uint8."""
        cfg, rig = self.cfg, self.rig
        kps = self.features.detect(left, self._margin)
        m = match_stereo(left, right, kps.xy, cfg)
        kp = kps.take(m.index)
        xy = np.rint(kp.xy)
        d = m.disparity
        z = rig.f * rig.baseline / d
        ok = (z >= cfg.min_depth) & (z <= cfg.max_depth)
        desc, has = self.features.describe(left, Keypoints(xy, kp.response, kp.size))
        ok &= has
        xy, d, desc, strength = xy[ok], d[ok], desc[ok], kp.response[ok]
        args = (xy[:, 1], xy[:, 0], d, rig.f, rig.cx, rig.cy, rig.baseline)
        points = triangulate(*args)
        cov = triangulation_covariance(*args, cfg.sigma_d, cfg.sigma_r, cfg.sigma_c)
        ids, length = self.tracker.update(xy, desc, points, cov)
        return StereoFrame(xy, d, strength, points, cov, desc, ids, length, len(kps), len(m.index))
