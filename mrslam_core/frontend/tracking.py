"""Frame-to-frame tracking of stereo points.

000 section 6.1: only points seen in 3 consecutive frames enter the filter. A point of the current
frame continues a track of the previous frame when their descriptors are mutual nearest neighbours
among the previous points inside a search window, with squared distance below
the descriptor's gate (``tracking_gate``) and a ratio test. A track missed in one frame ends.

The window comes from the camera's predicted motion (the robot's wheel odometry or the visual
odometry's last motion, with their uncertainty): each previous point is projected into the
current image and searched within the χ² gate of its predicted pixel covariance, so tracks
survive a turning robot and the fast, expanding image motion of a car. Without a prediction
(the first frames, after the visual odometry failed) the window is ``track_radius_px`` around
the frame's common image motion, the median displacement of the distinctive mutual matches
within ``track_search_px``.

Descriptors alone let a look-alike continue a track, and a wrong stereo match gives a track one
wrong 3D point; the frontend's visual odometry (``mrslam_core.frontend.odometry``) fits the
camera's motion to the candidate continuations and ends those outside its χ² gate.
"""

from __future__ import annotations

import numpy as np

from mrslam_core.frontend.config import FrontendConfig
from mrslam_core.frontend.features import descriptor_distance
from mrslam_core.linalg import sym_inv_det


class Tracker:
    """Track ids and consecutive-frame counts of the points of successive frames.

    Args:
        cfg: tracking gates (``tracking_gate``, ``track_ratio``, ``track_radius_px``).
    """

    def __init__(self, cfg: FrontendConfig):
        self.cfg = cfg
        self.next_id = 0
        self.shift = np.zeros(2)  # common image motion of the last update [px]
        self.reset()

    def reset(self) -> None:
        """Forget the previous frame (tracks end; ids keep increasing)."""
        self._xy = np.zeros((0, 2))
        self._desc = np.zeros((0, 0), np.float32)
        self._ids = np.zeros(0, np.int64)
        self._length = np.zeros(0, np.int64)
        self._points = np.zeros((0, 3))
        self._cov = np.zeros((0, 3, 3))

    def _common_motion(self, dist: np.ndarray, disp: np.ndarray, min_matches: int = 8) -> np.ndarray:
        """(2,) median image motion of the distinctive mutual matches within ``track_search_px``
        (ratio 0.8, distance below the gate); zero when fewer than ``min_matches`` agree."""
        search = self.cfg.track_search_px
        if search <= self.cfg.track_radius_px or dist.shape[0] < min_matches or dist.shape[1] < 2:
            return np.zeros(2)
        d = np.where((disp**2).sum(axis=2) <= search**2, dist, np.inf)
        n = d.shape[0]
        best = np.argmin(d, axis=1)
        d_best = d[np.arange(n), best]
        second = np.partition(d, 1, axis=1)[:, 1]
        ok = (d_best <= self.cfg.tracking_gate) & (d_best < 0.64 * second)
        ok &= np.argmin(d, axis=0)[best] == np.arange(n)
        if ok.sum() < min_matches:
            return np.zeros(2)
        return np.median(disp[np.flatnonzero(ok), best[ok]], axis=0)

    @property
    def previous(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The previous frame's (T, 2) pixels, (T, 3) points and (T, 3, 3) covariances."""
        return self._xy, self._points, self._cov

    def match(self, xy: np.ndarray, desc: np.ndarray, window: tuple | None = None) -> np.ndarray:
        """Which previous point each of this frame's points continues, by descriptor in a window.

        Args:
            xy: (N, 2) rectified left-image positions (column, row) [px].
            desc: (N, D) unit descriptors.
            window: where the previous points are expected in this image, from a predicted
                camera motion: (uv (T, 2) [px], covariance (T, 2, 2) [px²], usable (T,) bool);
                a point is a candidate inside the ``track_window_gate`` (χ², 2 dof) of its
                prediction. None: no motion is known, and the window is ``track_radius_px``
                around the frame's common image motion.

        Returns:
            (N,) int64 index into the previous frame's points, −1 where no track continues.
        """
        n, t = xy.shape[0], self._ids.size
        prev = np.full(n, -1, np.int64)
        if not (n and t and self._desc.shape[1] == desc.shape[1]):
            return prev
        dist = descriptor_distance(desc, self._desc)  # (N, T)
        if window is None:
            disp = xy[:, None, :] - self._xy[None, :, :]  # (N, T, 2) image motion [px]
            self.shift = self._common_motion(dist, disp)
            inside = ((disp - self.shift) ** 2).sum(axis=2) <= self.cfg.track_radius_px**2
        else:
            uv, cov, usable = window
            inv, _ = sym_inv_det(cov)
            diff = xy[:, None, :] - uv[None, :, :]
            inside = np.einsum("nti,tij,ntj->nt", diff, inv, diff) <= self.cfg.track_window_gate
            inside &= usable[None, :]
            self.shift = np.median(uv - self._xy, axis=0) if usable.any() else np.zeros(2)
        dist = np.where(inside, dist, np.inf)
        best = np.argmin(dist, axis=1)
        d_best = dist[np.arange(n), best]
        second = np.partition(dist, 1, axis=1)[:, 1] if t > 1 else np.full(n, np.inf)
        mutual = np.argmin(dist, axis=0)[best] == np.arange(n)
        ok = (
            np.isfinite(d_best)
            & (d_best <= self.cfg.tracking_gate)
            & (d_best < self.cfg.track_ratio**2 * second)
            & mutual
        )
        prev[ok] = best[ok]
        return prev

    def commit(
        self, xy: np.ndarray, desc: np.ndarray, points: np.ndarray, cov: np.ndarray,
        prev: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Give this frame's points their track ids and make it the previous frame.

        Args:
            xy, desc: as in :meth:`match`.
            points, cov: (N, 3), (N, 3, 3) the points in the rectified left camera [m, m²].
            prev: (N,) index of the continued previous point, −1 for a new track.

        Returns:
            (track_ids (N,) int64, length (N,) int64: consecutive frames seen, this one included).
        """
        n = xy.shape[0]
        ids = np.empty(n, np.int64)
        length = np.ones(n, np.int64)
        cont = prev >= 0
        ids[cont] = self._ids[prev[cont]]
        length[cont] = self._length[prev[cont]] + 1
        fresh = ~cont
        ids[fresh] = self.next_id + np.arange(int(fresh.sum()))
        self.next_id += int(fresh.sum())
        self._xy = np.asarray(xy, float).copy()
        self._desc = np.asarray(desc, np.float32).copy()
        self._ids = ids.copy()
        self._length = length.copy()
        self._points = np.asarray(points, float).reshape(-1, 3).copy()
        self._cov = np.asarray(cov, float).reshape(-1, 3, 3).copy()
        return ids, length
