"""Stereo camera model from CameraInfo-like data, rectification maps, and the EuRoC loader.

Frames: the left camera's optical frame (x right, y down, z forward) before rectification is what a
``t_base_cam`` extrinsic refers to, as a ROS tf ``robotN/camera_left_optical`` would. Rectification
rotates it by the CameraInfo ``R`` (p_rect = R · p_cam); the frontend triangulates in the RECTIFIED
left frame and moves points to base_link with ``t_base_rect = t_base_cam · [Rᵀ | 0]``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import yaml

from mrslam_core.frontend.errors import CameraModelError

_PINHOLE_MODELS = ("plumb_bob", "radial-tangential", "radtan", "rational_polynomial")
_FISHEYE_MODELS = ("equidistant",)


@dataclass(frozen=True)
class CameraCalibration:
    """One camera's calibration, laid out like sensor_msgs/CameraInfo (no ROS types).

    Attributes:
        width: image width [px].
        height: image height [px].
        K: (3, 3) intrinsics of the raw image [px].
        D: (n,) distortion coefficients (plumb_bob: k1 k2 p1 p2 [k3]; equidistant: k1..k4).
        R: (3, 3) rectification rotation, p_rect = R · p_cam.
        P: (3, 4) projection of the rectified image [px]; for the right camera P[0, 3] = −f·b.
        distortion_model: ``plumb_bob``, ``radial-tangential``, ``rational_polynomial`` or
            ``equidistant``.
    """

    width: int
    height: int
    K: np.ndarray
    D: np.ndarray
    R: np.ndarray
    P: np.ndarray
    distortion_model: str = "plumb_bob"

    def __post_init__(self) -> None:
        try:
            k = np.asarray(self.K, dtype=float).reshape(3, 3)
            r = np.asarray(self.R, dtype=float).reshape(3, 3)
            p = np.asarray(self.P, dtype=float).reshape(3, 4)
            d = np.asarray(self.D, dtype=float).reshape(-1)
        except (ValueError, TypeError) as exc:
            raise CameraModelError(f"camera info arrays have wrong sizes: {exc}") from exc
        for name, arr in (("K", k), ("R", r), ("P", p), ("D", d)):
            if not np.all(np.isfinite(arr)):
                raise CameraModelError(f"camera info {name} has non-finite values")
        if int(self.width) <= 0 or int(self.height) <= 0:
            raise CameraModelError(f"camera info size {self.width}x{self.height} is empty")
        if k[0, 0] <= 0 or k[1, 1] <= 0 or p[0, 0] <= 0 or p[1, 1] <= 0:
            raise CameraModelError("camera info K or P has a zero focal length (not calibrated?)")
        if not np.allclose(r @ r.T, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
            raise CameraModelError("camera info R is not a rotation")
        if self.distortion_model not in _PINHOLE_MODELS + _FISHEYE_MODELS:
            raise CameraModelError(f"unsupported distortion model {self.distortion_model!r}")
        if self.distortion_model in _FISHEYE_MODELS and d.size != 4:
            raise CameraModelError("equidistant distortion needs 4 coefficients")
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        for name, arr in (("K", k), ("R", r), ("P", p), ("D", d)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def is_rectified(self) -> bool:
        """True when the raw image already is the rectified one (no distortion, R = I, P = K)."""
        return bool(
            np.all(self.D == 0)
            and np.allclose(self.R, np.eye(3))
            and np.allclose(self.P[:, :3], self.K)
        )

    def rectification_maps(self) -> tuple[np.ndarray, np.ndarray]:
        """cv2.remap maps (fixed point, CV_16SC2) raw -> rectified, same size as the raw image."""
        size = (self.width, self.height)
        if self.distortion_model in _FISHEYE_MODELS:
            return cv2.fisheye.initUndistortRectifyMap(
                self.K, self.D, self.R, self.P[:, :3], size, cv2.CV_16SC2
            )
        return cv2.initUndistortRectifyMap(self.K, self.D, self.R, self.P[:, :3], size, cv2.CV_16SC2)


class StereoRig:
    """A calibrated horizontal stereo pair: rectification and the rectified pinhole parameters.

    Args:
        left: left camera calibration.
        right: right camera calibration.
        t_base_cam: (4, 4) base_link <- left camera optical frame (unrectified) [m].

    Raises:
        CameraModelError: sizes differ, the rectified projections disagree, the right camera is
            not to the right (P_right[0, 3] must be < 0), or the extrinsic is not rigid.
    """

    def __init__(self, left: CameraCalibration, right: CameraCalibration, t_base_cam: np.ndarray):
        if (left.width, left.height) != (right.width, right.height):
            raise CameraModelError("left and right camera info sizes differ")
        pl, pr = left.P, right.P
        if not np.allclose(pl[:, :3], pr[:, :3], rtol=1e-6, atol=1e-6):
            raise CameraModelError("left and right rectified projections P[:, :3] differ")
        if abs(pl[0, 3]) > 1e-9 or abs(pr[1, 3]) > 1e-9 or abs(pr[2, 3]) > 1e-9:
            raise CameraModelError("P does not describe a horizontal pair with the left as reference")
        if pr[0, 3] >= 0:
            raise CameraModelError("right camera P[0, 3] must be -f*baseline < 0")
        if abs(pl[0, 0] - pl[1, 1]) > 1e-3 * pl[0, 0]:
            raise CameraModelError("rectified fx and fy differ; triangulation assumes square pixels")
        t = np.asarray(t_base_cam, dtype=float)
        if t.shape != (4, 4) or not np.all(np.isfinite(t)):
            raise CameraModelError("t_base_cam must be a finite 4x4 matrix")
        rot = t[:3, :3]
        if not np.allclose(rot @ rot.T, np.eye(3), atol=1e-6) or np.linalg.det(rot) < 0:
            raise CameraModelError("t_base_cam rotation is not a rotation")
        self.left = left
        self.right = right
        self.width = left.width
        self.height = left.height
        self.f = float(pl[0, 0])
        self.cx = float(pl[0, 2])
        self.cy = float(pl[1, 2])
        self.baseline = float(-pr[0, 3] / pr[0, 0])
        unrect = np.eye(4)
        unrect[:3, :3] = left.R.T
        self.t_base_rect = t @ unrect
        self.needs_rectification = not (left.is_rectified and right.is_rectified)
        self._maps = (
            (left.rectification_maps(), right.rectification_maps())
            if self.needs_rectification
            else None
        )

    def rectify(self, left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rectified grey images (H, W) uint8 from raw grey images of the calibrated size."""
        if self._maps is None:
            return left, right
        (l1, l2), (r1, r2) = self._maps
        return (
            cv2.remap(left, l1, l2, cv2.INTER_LINEAR),
            cv2.remap(right, r1, r2, cv2.INTER_LINEAR),
        )

    @classmethod
    def rectified(
        cls, width: int, height: int, f: float, cx: float, cy: float, baseline: float,
        t_base_cam: np.ndarray,
    ) -> StereoRig:
        """A rig whose images arrive rectified (e.g. the simulator): D = 0, R = I, P = [K | t]."""
        k = np.array([[f, 0, cx], [0, f, cy], [0, 0, 1.0]])
        pl = np.hstack([k, np.zeros((3, 1))])
        pr = pl.copy()
        pr[0, 3] = -f * baseline
        left = CameraCalibration(width, height, k, np.zeros(5), np.eye(3), pl)
        right = CameraCalibration(width, height, k, np.zeros(5), np.eye(3), pr)
        return cls(left, right, t_base_cam)


def _read_euroc_sensor(path: Path) -> dict:
    text = path.read_text()
    lines = [ln for ln in text.splitlines() if not ln.startswith("%YAML")]
    return yaml.safe_load("\n".join(lines))


def load_euroc_stereo(folder: str | Path) -> StereoRig:
    """Stereo rig of an EuRoC MAV sequence (``cam0/sensor.yaml``, ``cam1/sensor.yaml``).

    R and P come from cv2.stereoRectify (zero disparity at infinity, alpha 0: only valid pixels).
    base_link is the EuRoC body (IMU) frame: ``t_base_cam`` is cam0's T_BS.

    Raises:
        CameraModelError: missing or malformed sensor.yaml.
    """
    folder = Path(folder)
    try:
        s0 = _read_euroc_sensor(folder / "cam0" / "sensor.yaml")
        s1 = _read_euroc_sensor(folder / "cam1" / "sensor.yaml")
        t0 = np.asarray(s0["T_BS"]["data"], dtype=float).reshape(4, 4)
        t1 = np.asarray(s1["T_BS"]["data"], dtype=float).reshape(4, 4)
        k0, k1 = (np.array([[s["intrinsics"][0], 0, s["intrinsics"][2]],
                            [0, s["intrinsics"][1], s["intrinsics"][3]], [0, 0, 1.0]])
                  for s in (s0, s1))
        d0 = np.asarray(s0["distortion_coefficients"], dtype=float)
        d1 = np.asarray(s1["distortion_coefficients"], dtype=float)
        w, h = (int(v) for v in s0["resolution"])
        model = str(s0["distortion_model"])
    except (OSError, KeyError, TypeError, ValueError, yaml.YAMLError) as exc:
        raise CameraModelError(f"cannot read EuRoC calibration in {folder}: {exc}") from exc
    t_c1_c0 = np.linalg.inv(t1) @ t0
    r1, r2, p1, p2, *_ = cv2.stereoRectify(
        k0, d0, k1, d1, (w, h), t_c1_c0[:3, :3].copy(), t_c1_c0[:3, 3].reshape(3, 1).copy(),
        flags=cv2.CALIB_ZERO_DISPARITY, alpha=0.0,
    )
    left = CameraCalibration(w, h, k0, d0, r1, p1, model)
    right = CameraCalibration(w, h, k1, d1, r2, p2, model)
    return StereoRig(left, right, t0)
