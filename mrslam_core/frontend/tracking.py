"""Frame-to-frame tracking of stereo points, and the choice of the B observations per frame.

000 section 6.1: only points seen in 3 consecutive frames enter the filter. A point of the current
frame continues a track of the previous frame when their descriptors are mutual nearest neighbours
among the previous points within ``track_radius_px`` in the image, with squared distance below
``track_descriptor_gate`` and a ratio test. A track missed in one frame ends.

A turning robot moves the whole image (about f·ω/rate pixels per frame: 55 px at 1.2 rad/s and
5 Hz with the simulator's head), so the gate is centred on the frame's common image motion,
the median displacement of the distinctive mutual matches within ``track_search_px``.

Descriptors alone let a look-alike continue a track, and a wrong stereo match gives a track one
wrong 3D point; with ``track_consistency_gate`` set, the continued tracks must also agree with
one rigid motion of the camera between the two frames (RANSAC on their 3D points, as stereo
visual odometry checks its matches), and those that do not end there.
"""

from __future__ import annotations

import numpy as np

from mrslam_core.frontend.config import FrontendConfig
from mrslam_core.frontend.features import descriptor_distance
from mrslam_core.geometry.rigid3d import fit_rigid_3d
from mrslam_core.linalg import quad_form, sym_inv_det

#: Fewer continued tracks than this cannot be checked against a rigid motion (a 3-point fit
#: with one point to test it); they are kept as the descriptors matched them.
MIN_CHECKED_TRACKS = 4


class Tracker:
    """Track ids and consecutive-frame counts of the points of successive frames.

    Args:
        cfg: tracking gates (``track_descriptor_gate``, ``track_ratio``, ``track_radius_px``).
    """

    def __init__(self, cfg: FrontendConfig):
        self.cfg = cfg
        self.next_id = 0
        self.shift = np.zeros(2)  # common image motion of the last update [px]
        self.inconsistent = 0  # continued tracks ended by the rigid-motion check, in all
        self.rng = np.random.default_rng(0)  # RANSAC samples; fixed, so runs repeat
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
        ok = (d_best <= self.cfg.track_descriptor_gate) & (d_best < 0.64 * second)
        ok &= np.argmin(d, axis=0)[best] == np.arange(n)
        if ok.sum() < min_matches:
            return np.zeros(2)
        return np.median(disp[np.flatnonzero(ok), best[ok]], axis=0)

    def update(
        self, xy: np.ndarray, desc: np.ndarray, points: np.ndarray | None = None,
        cov: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Associate this frame's points with the previous frame's.

        Args:
            xy: (N, 2) rectified left-image positions (column, row) [px].
            desc: (N, D) unit descriptors.
            points, cov: (N, 3) their 3D points and (N, 3, 3) covariances in the camera frame
                [m, m²], for the rigid-motion check (``track_consistency_gate``); None: no check.

        Returns:
            (track_ids (N,) int64, length (N,) int64: consecutive frames seen, this one included).
        """
        n = xy.shape[0]
        ids = np.empty(n, np.int64)
        length = np.ones(n, np.int64)
        matched = np.zeros(n, bool)
        t = self._ids.size
        if n and t and self._desc.shape[1] == desc.shape[1]:
            dist = descriptor_distance(desc, self._desc)  # (N, T)
            disp = xy[:, None, :] - self._xy[None, :, :]  # (N, T, 2) image motion [px]
            self.shift = self._common_motion(dist, disp)
            pix2 = ((disp - self.shift) ** 2).sum(axis=2)
            dist = np.where(pix2 <= self.cfg.track_radius_px**2, dist, np.inf)
            best = np.argmin(dist, axis=1)
            d_best = dist[np.arange(n), best]
            if t > 1:
                second = np.partition(dist, 1, axis=1)[:, 1]
            else:
                second = np.full(n, np.inf)
            mutual = np.argmin(dist, axis=0)[best] == np.arange(n)
            matched = (
                np.isfinite(d_best)
                & (d_best <= self.cfg.track_descriptor_gate)
                & (d_best < self.cfg.track_ratio**2 * second)
                & mutual
            )
            if points is not None and self.cfg.track_consistency_gate > 0 and self._points.shape[0] == t:
                cur = np.flatnonzero(matched)
                ok = self._consistent(points[cur], cov[cur], self._points[best[cur]], self._cov[best[cur]])
                matched[cur[~ok]] = False
                self.inconsistent += int((~ok).sum())
            ids[matched] = self._ids[best[matched]]
            length[matched] = self._length[best[matched]] + 1
        fresh = ~matched
        ids[fresh] = self.next_id + np.arange(int(fresh.sum()))
        self.next_id += int(fresh.sum())
        self._xy = np.asarray(xy, float).copy()
        self._desc = np.asarray(desc, np.float32).copy()
        self._ids = ids.copy()
        self._length = length.copy()
        if points is not None and self.cfg.track_consistency_gate > 0:
            self._points = np.asarray(points, float).copy()
            self._cov = np.asarray(cov, float).copy()
        else:
            self._points, self._cov = np.zeros((0, 3)), np.zeros((0, 3, 3))
        return ids, length

    def _consistent(self, cur: np.ndarray, cur_cov: np.ndarray, prev: np.ndarray, prev_cov: np.ndarray) -> np.ndarray:
        """(P,) bool: which of P continued tracks agree with the camera's rigid motion.

        RANSAC over ``track_ransac_hypotheses`` 3-point samples of prev ≈ R·cur + t; a pair is an
        inlier when ν = prev − (R·cur + t) has νᵀ(Σ_prev + R Σ_cur Rᵀ)⁻¹ν ≤ the gate. The motion of
        the largest consensus is refitted on its inliers and the pairs classified again.
        """
        p = cur.shape[0]
        if p < MIN_CHECKED_TRACKS:
            return np.ones(p, bool)
        gate = self.cfg.track_consistency_gate
        samples = np.argsort(self.rng.random((self.cfg.track_ransac_hypotheses, p)), axis=1)[:, :3]
        rot, trans = fit_rigid_3d(cur[samples], prev[samples])  # (H, 3, 3), (H, 3)

        def inliers(rot, trans):
            nu = prev - (np.einsum("...ij,pj->...pi", rot, cur) + trans[..., None, :])
            s = prev_cov + np.einsum("...ij,pjk,...lk->...pil", rot, cur_cov, rot)
            inv, _ = sym_inv_det(s)
            return quad_form(nu, inv) <= gate

        votes = inliers(rot, trans)  # (H, P)
        best = votes[np.argmax(votes.sum(axis=1))]
        if best.sum() < 3:
            return best
        rot, trans = fit_rigid_3d(cur[best], prev[best])
        return inliers(rot, trans)


def select_spread(
    xy: np.ndarray, strength: np.ndarray, eligible: np.ndarray, k: int,
    width: int, height: int, cols: int, rows: int,
) -> np.ndarray:
    """Indices of at most k eligible points, spread over a cols × rows image grid.

    Round-robin over grid cells: every occupied cell gives its strongest point first, then its
    second strongest, and so on; within a round, stronger points come first.

    Args:
        xy: (N, 2) image positions (column, row) [px].
        strength: (N,) larger is better.
        eligible: (N,) bool.
        k: at most this many.
        width, height: image size [px].
        cols, rows: grid size.

    Returns:
        (≤ k,) int64 indices into the N points, in selection order.
    """
    idx = np.nonzero(eligible)[0]
    if idx.size <= k:
        return idx[np.argsort(-strength[idx], kind="stable")]
    cx = np.clip((xy[idx, 0] * cols // width).astype(np.int64), 0, cols - 1)
    cy = np.clip((xy[idx, 1] * rows // height).astype(np.int64), 0, rows - 1)
    cell = cy * cols + cx
    order = np.lexsort((-strength[idx], cell))  # by cell, strongest first within a cell
    cell_sorted = cell[order]
    first = np.r_[0, np.nonzero(np.diff(cell_sorted))[0] + 1]
    starts = np.repeat(first, np.diff(np.r_[first, cell_sorted.size]))
    rank = np.arange(cell_sorted.size) - starts  # rank within the cell
    pick = np.lexsort((-strength[idx][order], rank))[:k]
    return idx[order][pick]
