"""A robot's odometry input to the central mapper: wheel, visual, or both fused.

:class:`OdometrySource` routes one robot's wheel and visual odometry to the poses the mapper
takes, by its configured source; the central node, the offline replay and the in-process team
all use it.

``wheel`` and ``visual`` pass one source's planar poses through. ``fused`` combines them step by
step: at each visual odometry pose (the frontend's frame stamps), the visual step since the
previous one and the wheel odometry's step over the same interval (interpolated from its pose
stream) are averaged with their information matrices,

    Δ = (Qw⁻¹ + Qv⁻¹)⁻¹ (Qw⁻¹·Δw + Qv⁻¹·Δv),

Qv the visual step's covariance (its twist covariance times the interval squared) and Qw the
wheel step's under the wheels' noise model (a :class:`MotionConfig`, through
:func:`mrslam_core.slam.motion.predict_motion`),
and Δ is chained onto the fused pose. A step the visual odometry could not estimate arrives with
the constant-velocity prediction and its large covariance, so the wheels carry it; a wheel that
slips is outvoted by the images. Steps are short (one frame), so their angles are averaged as
numbers.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from mrslam_core.evaluation.metrics import interpolate_poses
from mrslam_core.geometry.se2 import between, compose, wrap_angle
from mrslam_core.slam.config import MotionConfig
from mrslam_core.slam.motion import predict_motion

SOURCES = ("wheel", "visual", "fused")


def fuse_steps(wheel: np.ndarray, wheel_cov: np.ndarray, visual: np.ndarray, visual_cov: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """Information-weighted mean of two estimates (3,) of one planar step with (3, 3) covariances.

    Returns:
        (step (3,) [m, m, rad], covariance (3, 3)).
    """
    iw = np.linalg.inv(wheel_cov)
    iv = np.linalg.inv(visual_cov)
    cov = np.linalg.inv(iw + iv)
    dv = np.asarray(visual, float).copy()
    dv[2] = float(wheel[2]) + float(wrap_angle(dv[2] - wheel[2]))  # the same branch as the wheel's
    step = cov @ (iw @ np.asarray(wheel, float) + iv @ dv)
    step[2] = float(wrap_angle(step[2]))
    return step, 0.5 * (cov + cov.T)


def visual_step_covariance(cov6: np.ndarray) -> np.ndarray:
    """(3, 3) covariance of a frame's planar visual step (x [m], y [m], θ [rad]), from its (6, 6)
    covariance over (δθ, δt) (:class:`~mrslam_core.frontend.frontend.VisualOdometry`): the x, y of
    the translation and the turn about z. Over the frame interval dt it is the body twist's
    covariance times dt² (what :meth:`OdometryFusion.add_visual` takes, divided by dt²)."""
    return np.asarray(cov6, float)[np.ix_([3, 4, 2], [3, 4, 2])]


class OdometryFusion:
    """Fused planar odometry of one robot from its wheel and visual odometry streams.

    Args:
        motion: the wheel odometry's noise model.
        max_pending: visual poses kept while the wheel odometry has not reached their stamp.

    Attributes:
        dropped: visual poses that could not be fused (older than the wheel stream's start, or
            pushed out of the pending queue).
    """

    def __init__(self, motion: MotionConfig, max_pending: int = 50):
        self.motion = motion
        self._wheel: deque[tuple[int, np.ndarray]] = deque(maxlen=2000)
        self._pending: deque[tuple[int, np.ndarray, np.ndarray]] = deque()
        self._max_pending = max_pending
        self._last: tuple[int, np.ndarray, np.ndarray] | None = None  # stamp, visual pose, fused pose
        self.dropped = 0

    def add_wheel(self, stamp_ns: int, pose: np.ndarray) -> list[tuple[int, np.ndarray]]:
        """A wheel odometry pose (3,) at ``stamp_ns``; returns the fused poses it completes."""
        if self._wheel and stamp_ns <= self._wheel[-1][0]:
            return []
        self._wheel.append((int(stamp_ns), np.asarray(pose, float)))
        return self._drain()

    def add_visual(self, stamp_ns: int, pose: np.ndarray, twist_cov: np.ndarray) -> list[tuple[int, np.ndarray]]:
        """A visual odometry pose (3,) with the (3, 3) covariance of its body twist (vx, vy, ωz)
        at ``stamp_ns``; returns the fused poses (stamp, pose (3,)) now known, oldest first."""
        self._pending.append((int(stamp_ns), np.asarray(pose, float), np.asarray(twist_cov, float)))
        while len(self._pending) > self._max_pending:
            self._pending.popleft()
            self.dropped += 1
        return self._drain()

    def _drain(self) -> list[tuple[int, np.ndarray]]:
        out: list[tuple[int, np.ndarray]] = []
        if not self._wheel:
            return out
        t = np.array([s for s, _ in self._wheel], float)
        poses = np.array([p for _, p in self._wheel])

        def wheel_at(stamp_ns: int) -> np.ndarray:
            return interpolate_poses(np.array([float(stamp_ns)]), t, poses)[0]

        while self._pending:
            stamp, vpose, tcov = self._pending[0]
            if stamp > t[-1]:
                break  # the wheels have not reached it yet
            self._pending.popleft()
            if stamp < t[0]:
                self.dropped += 1
                continue
            if self._last is None:  # the first: the fused odometry starts at the wheel pose
                fused = wheel_at(stamp)
            else:
                t0, v0, f0 = self._last
                dt = (stamp - t0) * 1e-9
                dw = between(wheel_at(max(t0, int(t[0]))), wheel_at(stamp))
                qw = predict_motion(np.zeros((1, 3)), dw, self.motion, dt)[1][0]
                step, _ = fuse_steps(dw, qw, between(v0, vpose), tcov * dt**2 + 1e-12 * np.eye(3))
                fused = compose(f0, step)
            self._last = (stamp, vpose, fused)
            out.append((stamp, fused))
        return out


class OdometrySource:
    """One robot's odometry for the central mapper, from its configured source.

    Args:
        source: ``wheel`` (the wheel odometry's poses pass through), ``visual`` (the visual
            odometry's do) or ``fused`` (both, step by step: :class:`OdometryFusion`).
        wheel_motion: the wheel odometry's noise model (used by ``fused`` only).

    Attributes:
        source: the source's name.
        uses_wheel, uses_visual: which streams this source reads (the others are ignored).
        fusion: the :class:`OdometryFusion` of a ``fused`` source, else None.
    """

    def __init__(self, source: str, wheel_motion: MotionConfig):
        if source not in SOURCES:
            raise ValueError(f"odometry source must be one of {SOURCES}, not {source!r}")
        self.source = source
        self.uses_wheel = source in ("wheel", "fused")
        self.uses_visual = source in ("visual", "fused")
        self.fusion = OdometryFusion(wheel_motion) if source == "fused" else None

    @property
    def dropped(self) -> int:
        """Visual poses a ``fused`` source could not fuse (0 for the others)."""
        return 0 if self.fusion is None else self.fusion.dropped

    def wheel(self, stamp_ns: int, pose: np.ndarray) -> list[tuple[int, np.ndarray]]:
        """A wheel odometry pose (3,) [m, m, rad, odom frame]; returns the odometry poses (stamp,
        pose (3,)) for the mapper it completes, oldest first."""
        if self.fusion is not None:
            return self.fusion.add_wheel(stamp_ns, pose)
        return [(int(stamp_ns), np.asarray(pose, float))] if self.uses_wheel else []

    def visual(self, stamp_ns: int, pose: np.ndarray, twist_cov: np.ndarray) -> list[tuple[int, np.ndarray]]:
        """A visual odometry pose (3,) with its body twist's (3, 3) covariance (vx, vy, ωz); returns
        the odometry poses for the mapper it completes, oldest first."""
        if self.fusion is not None:
            return self.fusion.add_visual(stamp_ns, pose, twist_cov)
        return [(int(stamp_ns), np.asarray(pose, float))] if self.uses_visual else []


def propagate_planar(cov: np.ndarray, pose: np.ndarray, step: np.ndarray, step_cov: np.ndarray) -> np.ndarray:
    """Covariance (3, 3) of pose ⊕ step, from the pose's (3, 3) and the step's (3, 3) (step in the
    pose's body frame): F·Σ·Fᵀ + G·Q·Gᵀ, the Jacobians of compose (first order)."""
    th = float(pose[2])
    c, s = np.cos(th), np.sin(th)
    dx, dy = float(step[0]), float(step[1])
    f = np.array([[1.0, 0.0, -s * dx - c * dy], [0.0, 1.0, c * dx - s * dy], [0.0, 0.0, 1.0]])
    g = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return f @ cov @ f.T + g @ step_cov @ g.T
