"""Other robots' fiducial tags seen by the stereo head, as range-bearing robot sightings.

Each robot of :class:`~mrslam_core.frontend.config.FiducialConfig` carries its tag on the four
sides of a cube whose vertical axis stands above its base_link. A tag found in both rectified
images (OpenCV's ArUco detector, corners refined to sub-pixel) is triangulated corner by corner
(:func:`~mrslam_core.geometry.stereo.triangulate`); the face's normal comes from its four corners
in the left image (the poses of a square of known size that fit them, weighted by their
reprojection errors: :meth:`FiducialDetector.normals`); the point measured is the carrier's
axis, ``carrier_half`` behind the face's centre along the normal. Its covariance: the four
corners' triangulation covariance averaged, plus ``carrier_half`` times the normal's error
(``normal_sigma_px`` over the face's side in pixels) sideways, plus the spread between the poses
that fit. Moved into base_link, the axis gives the other robot's range and bearing (the same
measurement as MR.CLAM's robot readings, scored by the filter and used by rendezvous joins).

Frames: pixels (column, row) of the rectified left image; the left optical frame (x right, y down,
z forward); base_link (x forward, y left, z up). Ranges [m], bearings [rad] counter-clockwise
from base_link's x axis.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import cv2
import numpy as np

from mrslam_core.frontend.camera import StereoRig
from mrslam_core.frontend.config import FiducialConfig
from mrslam_core.geometry.stereo import optical_to_body, triangulate, triangulation_covariance
from mrslam_core.types import RobotSighting

#: χ²(1) at 0.999: the checks of a face's disparity against its size and of its height
CHI2_1 = 10.83


@dataclass(frozen=True)
class TagDetections:
    """What one stereo pair showed of the other robots' tags.

    Attributes:
        sightings: one per robot seen (its faces fused), in ``FiducialConfig.robots`` order.
        quads: (T, 4, 2) every detected tag's corners in the left image (column, row) [px], the
            region whose points are not landmarks.
    """

    sightings: tuple[RobotSighting, ...]
    quads: np.ndarray


def tag_object_points(size: float) -> np.ndarray:
    """(4, 3) a tag's corners in its own frame (x right, y up, z out of the face) [m], in the
    order OpenCV's detector returns them (top-left, top-right, bottom-right, bottom-left)."""
    h = size / 2
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def tag_image(cfg: FiducialConfig, tag: int, pixels: int = 256) -> np.ndarray:
    """(pixels, pixels) uint8 image of one carrier face: tag ``tag`` of ``cfg.dictionary``,
    ``cfg.tag_size`` of the face's 2·``carrier_half`` wide, centred on white."""
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, cfg.dictionary))
    side = int(round(pixels * cfg.tag_size / (2 * cfg.carrier_half)))
    img = np.full((pixels, pixels), 255, np.uint8)
    a = (pixels - side) // 2
    img[a:a + side, a:a + side] = cv2.aruco.generateImageMarker(dictionary, tag, side)
    return img


class FiducialDetector:
    """Finds the other robots' tags in rectified stereo pairs.

    Args:
        rig: the calibrated stereo rig (rectified intrinsics and base_link <- rectified left).
        cfg: the tags (``cfg.robots`` must not be empty).
        robot: the observing robot (its own tag is not reported).

    Attributes:
        drops: Counter of tags not turned into sightings, by reason: ``tag_unknown`` (an id no
            robot carries), ``tag_unpaired`` (not found alike in both images: :meth:`_pair`),
            ``tag_height`` (not at the carriers' height: not a robot's tag).
    """

    def __init__(self, rig: StereoRig, cfg: FiducialConfig, robot: str):
        if not cfg.robots:
            raise ValueError("FiducialDetector needs FiducialConfig.robots")
        self.rig, self.cfg, self.robot = rig, cfg, robot
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, cfg.dictionary))
        self._detector = cv2.aruco.ArucoDetector(dictionary, params)
        self._k = np.array([[rig.f, 0.0, rig.cx], [0.0, rig.f, rig.cy], [0.0, 0.0, 1.0]])
        self._object = tag_object_points(cfg.tag_size)
        self.drops: Counter[str] = Counter()

    def _find(self, image: np.ndarray) -> dict[int, list[np.ndarray]]:
        corners, ids, _ = self._detector.detectMarkers(image)
        found: dict[int, list[np.ndarray]] = {}
        for c, i in zip(corners, [] if ids is None else ids.ravel()):
            found.setdefault(int(i), []).append(np.asarray(c, float).reshape(4, 2))
        return found

    def detect(self, left: np.ndarray, right: np.ndarray) -> TagDetections:
        """Tags in a rectified grey pair (H, W) uint8, as sightings of the robots carrying them."""
        in_left = self._find(left)
        quads = [q for qs in in_left.values() for q in qs]
        robots = self.cfg.robots
        self.drops["tag_unknown"] += sum(len(lq) for tag, lq in in_left.items() if tag >= len(robots))
        others = {tag: lq for tag, lq in in_left.items() if tag < len(robots) and robots[tag] != self.robot}
        # the right image only pairs the left's tags of other robots: not searched without one
        in_right = self._find(right) if others else {}
        points: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
        for tag, lq in others.items():
            for ql, qr in self._pair(lq, in_right.get(tag, [])):
                axis = self._axis(ql, qr)
                if axis is not None:
                    points.setdefault(tag, []).append(axis)
        sightings = []
        for tag in sorted(points):
            xy, cov = _fuse(points[tag])
            z, zcov = _range_bearing(xy, cov)
            sightings.append(RobotSighting(self.robot, self.cfg.robots[tag], z, zcov))
        return TagDetections(tuple(sightings), np.array(quads, float).reshape(-1, 4, 2))

    def _pair(self, lq: list[np.ndarray], rq: list[np.ndarray]) -> list[tuple[np.ndarray, np.ndarray]]:
        """One tag's faces in the left and right images paired.

        A face looks the same in both images: rows within ``row_tolerance`` and the corners'
        layout about their centre within twice that. Its disparity agrees with its size: an
        upright tag's vertical edges of h px put it at f·tag_size/h, i.e. a disparity of
        baseline·h/tag_size, within χ²(1) at 0.999 of the two estimates' variances (corner
        noise ``sigma_px``). Each camera of the pair may see a different face of a far carrier:
        those do not pair. Faces without a partner are counted ``tag_unpaired``.
        """
        cfg, tol = self.cfg, self.cfg.row_tolerance
        var = cfg.sigma_px**2 * (0.5 + (self.rig.baseline / cfg.tag_size) ** 2)
        cost = np.full((len(lq), len(rq)), np.inf)
        for a, ql in enumerate(lq):
            h = 0.5 * (np.linalg.norm(ql[3] - ql[0]) + np.linalg.norm(ql[2] - ql[1]))
            expected = self.rig.baseline * h / cfg.tag_size
            for b, qr in enumerate(rq):
                shape = np.abs((ql - ql.mean(0)) - (qr - qr.mean(0))).max()
                chi2 = (np.mean(ql[:, 0] - qr[:, 0]) - expected) ** 2 / var
                if np.abs(ql[:, 1] - qr[:, 1]).max() <= tol and shape <= 2 * tol and chi2 <= CHI2_1:
                    cost[a, b] = chi2
        pairs = []
        while np.isfinite(cost).any():
            a, b = np.unravel_index(np.argmin(cost), cost.shape)
            pairs.append((lq[a], rq[b]))
            cost[a, :], cost[:, b] = np.inf, np.inf
        self.drops["tag_unpaired"] += len(lq) - len(pairs)
        return pairs

    def _axis(self, ql: np.ndarray, qr: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """The carrier's axis in base_link from one face's corners in both images: its (x, y)
        (2,) [m] and their covariance (2, 2) [m²]; None (counted) for a pair that is no tag."""
        cfg, rig = self.cfg, self.rig
        d = ql[:, 0] - qr[:, 0]
        args = (ql[:, 1], ql[:, 0], d, rig.f, rig.cx, rig.cy, rig.baseline)
        corners = triangulate(*args)
        s = cfg.sigma_px
        centre = corners.mean(axis=0)
        cov = triangulation_covariance(*args, np.sqrt(2.0) * s, s, s).sum(axis=0) / 16.0
        if cfg.carrier_half > 0:
            centre, cov = self._behind(ql, centre, cov)
        p, c = optical_to_body(centre[None], cov[None], rig.t_base_rect)
        p, c = p[0], c[0]
        if (p[2] - cfg.carrier_height) ** 2 > CHI2_1 * (c[2, 2] + cfg.height_tolerance**2):
            self.drops["tag_height"] += 1
            return None
        return p[:2], c[:2, :2]

    def normals(self, ql: np.ndarray, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A face's unit normals in the left optical frame, pointing at the camera, (S, 3), and
        their probabilities (S,).

        A small square seen nearly head-on fits two poses about equally (IPPE's two solutions,
        mirror images about the line of sight). The candidates are IPPE's two and SQPnP's one,
        each refined by Levenberg–Marquardt on the four corners; distinct ones are weighted by
        the likelihood of their reprojection error under ``sigma_px``. (OpenCV 5.0's IPPE alone
        is 4 px off on a face seen 78° from head-on, and 0.1 px and 10° off on float64 input.)
        The line of sight stands in when no pose fits.
        """
        obj, img = self._object, ql.reshape(-1, 1, 2)
        cands = []
        for flags in (cv2.SOLVEPNP_IPPE_SQUARE, cv2.SOLVEPNP_SQPNP):
            n_sol, rvecs, tvecs, _ = cv2.solvePnPGeneric(
                obj.astype(np.float32), img.astype(np.float32), self._k, None, flags=flags)
            for r, t in zip(rvecs[:n_sol], tvecs[:n_sol]):
                r, t = cv2.solvePnPRefineLM(obj, img, self._k, None, r.astype(float), t.astype(float))
                proj = cv2.projectPoints(obj, r, t, self._k, None)[0].reshape(4, 2)
                n = cv2.Rodrigues(r)[0][:, 2]
                if t.ravel()[2] > 0 and not any(np.abs(n - m).max() < 1e-3 for m, _ in cands):
                    cands.append((n, float(np.square(proj - ql).sum())))
        if not cands:
            return (-centre / np.linalg.norm(centre))[None], np.ones(1)
        n = np.array([c[0] for c in cands])
        n[n @ centre > 0] *= -1
        ll = -0.5 * np.array([c[1] for c in cands]) / self.cfg.sigma_px**2
        w = np.exp(ll - ll.max())
        return n, w / w.sum()

    def _behind(self, ql: np.ndarray, centre: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The carrier's axis (3,) and its covariance (3, 3), optical frame, from a face's
        centre and covariance: ``carrier_half`` behind the face along each of its normals
        (:meth:`normals`), each uncertain sideways by ``carrier_half`` × ``normal_sigma_px`` /
        the face's side [px], moment-matched over the normals' probabilities."""
        h = self.cfg.carrier_half
        side = np.linalg.norm(ql - np.roll(ql, 1, axis=0), axis=1).mean()
        sigma_n = self.cfg.normal_sigma_px / side
        normals, w = self.normals(ql, centre)
        axes = centre - h * normals
        mean = w @ axes
        spread = sum(wi * ((h * sigma_n) ** 2 * (np.eye(3) - np.outer(n, n)) + np.outer(a - mean, a - mean))
                     for wi, n, a in zip(w, normals, axes))
        return mean, cov + spread


def _fuse(points: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Information-weighted mean (2,) and covariance (2, 2) of one carrier's faces."""
    if len(points) == 1:
        return points[0]
    info = sum(np.linalg.inv(c) for _, c in points)
    cov = np.linalg.inv(info)
    return cov @ sum(np.linalg.solve(c, p) for p, c in points), cov


def _range_bearing(xy: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(range [m], bearing [rad]) (2,) of a base_link point (x, y) and its covariance (2, 2)."""
    x, y = xy
    r = float(np.hypot(x, y))
    jac = np.array([[x / r, y / r], [-y / r**2, x / r**2]])
    return np.array([r, np.arctan2(y, x)]), jac @ cov @ jac.T


def inside_quads(xy: np.ndarray, quads: np.ndarray, scale: float = 1.0, margin: float = 0.0) -> np.ndarray:
    """(N,) bool: pixel (column, row) ``xy`` (N, 2) inside one of the convex ``quads``
    (T, 4, 2), each grown about its centre by ``scale`` and then by ``margin`` [px] (a tag's
    whole carrier face: ``scale`` = face / tag side)."""
    out = np.zeros(len(xy), bool)
    for q in quads:
        centre = q.mean(axis=0)
        side = np.linalg.norm(q - np.roll(q, 1, axis=0), axis=1).mean()
        grown = centre + (q - centre) * (scale + 2.0 * margin / max(side, 1e-9))
        edge = np.roll(grown, -1, axis=0) - grown
        rel = xy[:, None, :] - grown[None]
        cross = edge[None, :, 0] * rel[..., 1] - edge[None, :, 1] * rel[..., 0]
        out |= (cross >= 0).all(axis=1) | (cross <= 0).all(axis=1)
    return out
