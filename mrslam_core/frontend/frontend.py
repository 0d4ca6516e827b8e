"""The stereo frontend: one step per stereo pair, observations and an obstacle scan out.

Per pair (000 sections 3.2, 6.1): rectify, detect in the left image (spread over a grid), match
along the rectified row, triangulate (eq. 12) with covariance R = J·Rsp·Jᵀ, describe, track over
frames in windows placed by the predicted camera motion, estimate the camera's motion from the
continued tracks (visual odometry, :mod:`mrslam_core.frontend.odometry`; tracks that disagree
with it end), and publish the points tracked for ``min_track_length`` consecutive frames, at most
B of them spread over the image, in base_link (x forward, y left, z up), with the visual
odometry's pose (:attr:`Frontend.odometry`).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import cv2
import numpy as np

from mrslam_core.frontend.camera import StereoRig
from mrslam_core.frontend.config import FiducialConfig, FrontendConfig
from mrslam_core.frontend.features import FeatureExtractor, Keypoints
from mrslam_core.frontend.fiducials import FiducialDetector, inside_quads
from mrslam_core.frontend.matching import match_stereo
from mrslam_core.frontend.odometry import CameraMotion, estimate_motion, predict_pixels, skew
from mrslam_core.frontend.obstacles import ObstacleScan, ObstacleScanner
from mrslam_core.frontend.spread import select_spread
from mrslam_core.frontend.tracking import Tracker
from mrslam_core.geometry.stereo import optical_to_body, triangulate, triangulation_covariance
from mrslam_core.types import ObservationSet, RobotSighting

#: a detected point this close to a tag's carrier face is on its edge [px]
TAG_MARGIN_PX = 2.0

ENCODINGS = {  # encoding -> (channels, dtype, conversion to grey)
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
        motion: the camera's motion since the previous frame from the visual odometry, None
            where it could not be estimated (or on a first frame).
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
    motion: CameraMotion | None = None


@dataclass(frozen=True)
class VisualOdometry:
    """The frontend's visual odometry after a frame, in base_link terms.

    Attributes:
        stamp_ns: the frame's stamp [ns].
        pose: (4, 4) T_odom_base, the base_link pose in the visual odometry's odom frame (base_link
            at the first frame) [m].
        delta: (4, 4) T_prev_cur, the base_link motion since the previous frame [m].
        cov: (6, 6) covariance of the motion, over (δθ, δt) of base_link (rotation vector in the
            current base frame [rad], translation in the previous base frame [m]).
        estimated: False when the frame's motion could not be estimated and the constant-velocity
            prediction (with its covariance) stands in.
    """

    stamp_ns: int
    pose: np.ndarray
    delta: np.ndarray
    cov: np.ndarray
    estimated: bool


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
    if encoding not in ENCODINGS:
        return None, "unsupported_encoding"
    channels, dtype, code = ENCODINGS[encoding]
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
        odometry: the visual odometry after the last processed pair (None before the first).
        vo_failures: processed pairs (after the first) whose motion could not be estimated.
        track_gaps: pairs after a gap longer than ``max_track_gap``: every track ended there.
        fiducials: the detector of the other robots' tags (None without a ``fiducials`` config
            naming robots); its ``drops`` count the tags not reported.
    """

    def __init__(self, rig: StereoRig, cfg: FrontendConfig | None = None, robot: str = "robot1",
                 fiducials: FiducialConfig | None = None):
        self.rig = rig
        self.cfg = cfg if cfg is not None else FrontendConfig()
        self.robot = robot
        self.features = FeatureExtractor(self.cfg)
        self.tracker = Tracker(self.cfg)
        self.scanner = ObstacleScanner(rig, self.cfg)
        self.fiducials = FiducialDetector(rig, fiducials, robot) if fiducials is not None and fiducials.robots else None
        self.drops: Counter[str] = Counter()
        self.frames = 0
        self.last_frame: StereoFrame | None = None
        self.last_error: str | None = None
        self._last_stamp: int | None = None
        self._margin = 2 * self.cfg.patch_radius + 1
        self.odometry: VisualOdometry | None = None
        self.vo_failures = 0
        self.track_gaps = 0
        self._velocity: CameraMotion | None = None  # last estimated motion: constant velocity
        self._tracking = False  # the last frame's motion was estimated: its velocity predicts

    def reset(self) -> None:
        """Forget tracks and the motion prior (e.g. after a gap in the stream); the visual
        odometry's pose is kept and continues from where it was."""
        self.tracker.reset()
        self._last_stamp = None
        self._velocity = None
        self._tracking = False

    def _prior(self) -> CameraMotion | None:
        """The constant-velocity prediction of this frame's camera motion, with its covariance:
        the last estimated motion, widened by ``prior_sigma_rot`` and ``prior_sigma_trans``."""
        if self._velocity is None:
            return None
        return CameraMotion(self._velocity.rotation, self._velocity.translation,
                            self._velocity.cov + self._prior_noise(), np.zeros(0, bool))

    def _drop(self, reason: str) -> tuple[None, None]:
        self.drops[reason] += 1
        return None, None

    def motion_prior(self, odometry: np.ndarray | None = None) -> CameraMotion | None:
        """The prediction of this frame's camera motion that places the tracks' search windows.

        Args:
            odometry: the robot's own (wheel) odometry since the previous frame, T_prev_cur of
                base_link (4, 4) [m].

        Returns:
            That motion in the camera, if given; else the constant-velocity prediction when the
            previous frame's motion was estimated; else None (the window falls back to the
            frame's common image motion). Either prediction is uncertain by ``prior_sigma_rot``
            and ``prior_sigma_trans`` per axis (the constant-velocity one also by the last
            motion's own covariance).
        """
        if odometry is not None:
            t_bc = self.rig.t_base_rect
            cam = np.linalg.inv(t_bc) @ np.asarray(odometry, float) @ t_bc
            return CameraMotion(cam[:3, :3], cam[:3, 3], self._prior_noise(), np.zeros(0, bool))
        return self._prior() if self._tracking else None

    def _prior_noise(self) -> np.ndarray:
        c = self.cfg
        return np.diag([c.prior_sigma_rot**2] * 3 + [c.prior_sigma_trans**2] * 3)

    def step(
        self, left: np.ndarray, right: np.ndarray, stamp_ns: int, *,
        right_stamp_ns: int | None = None, encoding: str | None = None,
        right_encoding: str | None = None, odometry: np.ndarray | None = None,
    ) -> tuple[ObservationSet | None, ObstacleScan | None]:
        """Process one stereo pair. Never raises: bad input is dropped and counted in ``drops``.

        Args:
            left, right: raw images (H, W) or (H, W, C) of the calibrated size.
            stamp_ns: left image time (ns); the observations carry it.
            right_stamp_ns: right image time (ns), checked against ``max_stamp_skew_ns``.
            encoding, right_encoding: ROS image encodings (None: inferred from the array;
                right_encoding defaults to encoding).
            odometry: the robot's wheel odometry since the previous pair, T_prev_cur of base_link
                (4, 4), to place the search windows (:meth:`motion_prior`); None: the visual
                odometry's own prediction.

        Returns:
            (observations in base_link, possibly empty; obstacle scan), or (None, None) for a drop.
        """
        try:
            return self._step(left, right, stamp_ns, right_stamp_ns, encoding,
                              right_encoding if right_encoding is not None else encoding, odometry)
        except Exception as exc:  # noqa: BLE001 - the frontend must keep running; counted below
            self.last_error = f"{type(exc).__name__}: {exc}"
            return self._drop("internal_error")

    def _step(self, left, right, stamp_ns, right_stamp_ns, encoding, right_encoding, odometry):
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
        if self._last_stamp is not None and stamp_ns - self._last_stamp > cfg.max_track_gap * 1e9:
            self.track_gaps += 1
            self.reset()  # the visual odometry takes no motion over the gap: it is not known
        first = self._last_stamp is None
        frame = self.process_rectified(gl, gr, None if first else self.motion_prior(odometry))
        self._advance_odometry(frame.motion, stamp_ns, first)
        self._last_stamp = stamp_ns
        self.frames += 1
        self.last_frame = frame
        eligible = frame.track_length >= cfg.min_track_length
        sightings: tuple[RobotSighting, ...] = ()
        if self.fiducials is not None:
            tags = self.fiducials.detect(gl, gr)
            sightings = tags.sightings
            # a tag is on a robot, which moves: the points on its carrier face are no landmarks
            f = self.fiducials.cfg
            face = 2 * f.carrier_half / f.tag_size if f.carrier_half > 0 else 1.0
            eligible &= ~inside_quads(frame.xy, tags.quads, face, TAG_MARGIN_PX)
        pick = select_spread(frame.xy, frame.strength, eligible, cfg.max_observations,
                             self.rig.width, self.rig.height, cfg.grid_cols, cfg.grid_rows)
        z, cov = optical_to_body(frame.points[pick], frame.cov[pick], self.rig.t_base_rect)
        obs = ObservationSet(self.robot, stamp_ns, z.reshape(-1, 3), cov.reshape(-1, 3, 3),
                             frame.descriptors[pick], frame.track_ids[pick], sightings)
        if cfg.obstacle_source == "dense":
            scan = self.scanner.from_images(gl, gr, stamp_ns)
        else:
            pts, _ = optical_to_body(frame.points, None, self.rig.t_base_rect)
            scan = self.scanner.from_points(pts, stamp_ns)
        return obs, scan

    def _advance_odometry(self, motion: CameraMotion | None, stamp_ns: int, first: bool) -> None:
        """Move the visual odometry's pose by this frame's camera motion (or its prediction)."""
        estimated = motion is not None
        if motion is None and not first:
            self.vo_failures += 1
            motion = self._prior()
        if motion is None:  # a first frame, or no prior yet: no motion, no information
            motion = CameraMotion.identity(self._prior_noise())
        self._velocity = motion if estimated else self._velocity
        self._tracking = estimated
        t_bc = self.rig.t_base_rect
        delta = t_bc @ motion.matrix() @ np.linalg.inv(t_bc)
        cov = _body_covariance(motion, t_bc)
        if self.odometry is None:  # the odom frame is base_link at the first frame
            pose, delta = np.eye(4), np.eye(4)
        else:
            pose = self.odometry.pose @ delta
        self.odometry = VisualOdometry(stamp_ns, pose, delta, cov, estimated or first)

    def process_rectified(self, left: np.ndarray, right: np.ndarray, prior: CameraMotion | None = None) -> StereoFrame:
        """Detect, match, triangulate, describe, track and estimate the camera's motion on a
        rectified grey pair (H, W) uint8; ``prior`` places the search windows (None: the frame's
        common image motion)."""
        cfg, rig = self.cfg, self.rig
        kps = self.features.detect(left, self._margin)
        m = match_stereo(left, right, kps.xy, cfg)
        kp = kps.take(m.index)
        xy = np.rint(kp.xy)
        d = m.disparity
        z = rig.f * rig.baseline / d
        ok = (z >= cfg.min_depth) & (z <= cfg.max_depth)
        desc, has = self.features.describe(left, Keypoints(xy, kp.response, kp.size, kp.octave))
        ok &= has
        xy, d, desc, strength = xy[ok], d[ok], desc[ok], kp.response[ok]
        args = (xy[:, 1], xy[:, 0], d, rig.f, rig.cx, rig.cy, rig.baseline)
        points = triangulate(*args)
        cov = triangulation_covariance(*args, cfg.sigma_d, cfg.sigma_r, cfg.sigma_c)
        _, prev_pts, prev_cov = self.tracker.previous
        window = None
        if prior is not None:
            window = predict_pixels(prior, prev_pts, prev_cov, rig.f, rig.cx, rig.cy, cfg.keypoint_sigma_px)
        prev = self.tracker.match(xy, desc, window)
        pairs = np.flatnonzero(prev >= 0)
        motion = estimate_motion(
            prev_pts[prev[pairs]], prev_cov[prev[pairs]], xy[pairs], points[pairs], cov[pairs],
            rig.f, rig.cx, rig.cy, gate=cfg.vo_gate, ransac_px=cfg.vo_ransac_px,
            ransac_iterations=cfg.vo_ransac_iterations, min_inliers=cfg.vo_min_inliers,
        ) if pairs.size else None
        if motion is not None:
            prev[pairs[~motion.inliers]] = -1  # inconsistent with the camera's motion: ends
        ids, length = self.tracker.commit(xy, desc, points, cov, prev)
        return StereoFrame(xy, d, strength, points, cov, desc, ids, length, len(kps), len(m.index), motion)


def _body_jacobian(rotation: np.ndarray, t_body_cam: np.ndarray) -> np.ndarray:
    """(6, 6) ∂(δθ_b, δt_b)/∂(δθ, δt) of a camera motion with rotation R moved to the body frame,
    T_b = A·T_c·A⁻¹ with A = T_body_cam = [R_a | t_a] (rotation vectors in the current frames,
    translations in the previous ones): δθ_b = R_a·δθ, δt_b = R_a·δt + R_b·[t_a]×·δθ_b."""
    r_a, t_a = t_body_cam[:3, :3], t_body_cam[:3, 3]
    r_b = r_a @ rotation @ r_a.T
    jac = np.zeros((6, 6))
    jac[:3, :3] = r_a
    jac[3:, 3:] = r_a
    jac[3:, :3] = r_b @ skew(t_a) @ r_a
    return jac


def _body_covariance(motion: CameraMotion, t_body_cam: np.ndarray) -> np.ndarray:
    """(6, 6) covariance of a camera motion moved to the body frame (:func:`_body_jacobian`)."""
    jac = _body_jacobian(motion.rotation, t_body_cam)
    return jac @ motion.cov @ jac.T
