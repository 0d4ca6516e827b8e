"""UTIAS Multi-Robot Cooperative Localization and Mapping (MR.CLAM) datasets.

Leung, Halpern, Barfoot, Liu: "The UTIAS Multi-Robot Cooperative Localization and Mapping
Dataset", IJRR 2011. Each dataset folder holds, per robot i = 1..5, ``Robot{i}_Odometry.dat``
(time [s], forward velocity [m/s], angular velocity [rad/s]), ``Robot{i}_Measurement.dat`` (time
[s], BARCODE, range [m], bearing [rad]) and ``Robot{i}_Groundtruth.dat`` (time [s], x [m], y [m],
θ [rad], Vicon), plus ``Barcodes.dat`` (subject → barcode: subjects 1–5 are the robots, 6–20 the
landmarks) and ``Landmark_Groundtruth.dat`` (subject, x, y, σx, σy).

The logs are not what happened, and :class:`MrclamCalibration` says how they relate (fitted
against Vicon by ``mrslam experiment mrclam_calibration``): the "range" a robot's camera reports
is the depth of the barcode along the optical axis (scaled and offset), not its distance, so it is
short by a factor cos(bearing) off the axis (0.13 m at 0.3 rad and 3 m); and the logged velocities
are the commanded ones, which the robots execute about 7 % slower.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from mrslam_core.errors import InputError
from mrslam_core.geometry.se2 import between, compose, wrap_angle
from mrslam_core.evaluation.metrics import interpolate_poses


class DatasetError(InputError, ValueError):
    """A dataset folder is missing files or holds malformed data."""


def read_dat(path: Path, columns: int) -> np.ndarray:
    """Whitespace-separated numeric table with '#' comments, shape (N, columns)."""
    if not path.is_file():
        raise DatasetError(f"missing file {path}")
    try:
        data = np.loadtxt(path, comments="#", ndmin=2)
    except ValueError as exc:
        raise DatasetError(f"{path}: not a numeric table: {exc}") from exc
    if data.shape[1] != columns:
        raise DatasetError(f"{path}: expected {columns} columns, found {data.shape[1]}")
    return data


@dataclass(frozen=True)
class MrclamCalibration:
    """How a MR.CLAM robot's logs relate to its motion and to the scene.

    A reading of a subject at depth z [m] along the camera's optical axis (z = r·cos b for a
    subject at distance r and bearing b from the robot's centre) is ``range_offset[i-1] +
    range_scale[i-1] · z`` for robot i's camera; :meth:`MrclamDataset.calibrated` turns it into
    r. A bearing read by robot i's camera is the true bearing plus ``bearing_offset[i-1]`` (the
    camera's yaw on the robot). A single value applies to every camera. A logged (v, ω) is executed as
    (``velocity_scale`` · v, ``turn_rate_scale`` · ω), the same for every robot.

    Defaults: dataset 6 against Vicon (``mrslam experiment mrclam_calibration
    ../shared/data/mrclam/dataset6``, docs/results.md). Each camera has its own line: the lines
    fitted to the first, middle and last third of the run agree within 0.004-0.009 in scale
    for each camera, while robot 2's camera reads 2.9 % longer than the pooled line (0.062 m
    residual σ under the other four's line, 0.026 m under its own). The executed velocity
    shares are pooled over all robots: one robot's share changes by up to 7 % from one half of
    the run to the other, more than the robots differ. All nine MR.CLAM datasets were recorded
    by the same five robots (the ASRL dataset page). Identity: offset 0, scales 1.

    Attributes:
        range_offset: reading at zero depth [m], per camera (robot 1 first) or one for all.
        range_scale: reading per metre of depth [-], per camera or one for all.
        bearing_offset: read minus true bearing [rad], per camera or one for all (robot 4's
            camera: −0.77°, −0.56° / −1.13° / −0.73° over the thirds of dataset 6 and −0.60° on
            its readings of robots; the others within ±0.25°).
        velocity_scale: executed share of the logged forward velocity [-].
        turn_rate_scale: executed share of the logged turn rate [-].
    """

    range_offset: tuple[float, ...] = (0.041, 0.006, 0.050, 0.093, 0.045)
    range_scale: tuple[float, ...] = (1.016, 1.051, 1.012, 1.021, 1.020)
    bearing_offset: tuple[float, ...] = (-0.0003, 0.0044, -0.0017, -0.0134, -0.0007)
    velocity_scale: float = 0.934
    turn_rate_scale: float = 0.926

    def __post_init__(self) -> None:
        for name in ("range_offset", "range_scale", "bearing_offset"):
            value = getattr(self, name)
            if isinstance(value, (int, float)):  # one line for every camera
                object.__setattr__(self, name, (float(value),))
            elif not len(value):
                raise ValueError(f"{name} must hold one value per camera or one for all, got none")
        if not (min(self.range_scale) > 0 and self.velocity_scale > 0 and self.turn_rate_scale > 0):
            raise ValueError("range_scale, velocity_scale and turn_rate_scale must be > 0")

    def _pick(self, name: str, robot: int) -> float:
        values = getattr(self, name)
        if len(values) == 1:
            return values[0]
        if not 1 <= robot <= len(values):
            raise ValueError(f"{name} holds {len(values)} cameras, no value for robot {robot}")
        return values[robot - 1]

    def line(self, robot: int) -> tuple[float, float]:
        """Robot ``robot``'s camera line (offset [m], scale)."""
        return self._pick("range_offset", robot), self._pick("range_scale", robot)

    def bearing_of(self, bearing: np.ndarray, robot: int) -> np.ndarray:
        """True bearing [rad] of subjects robot ``robot``'s camera read at ``bearing`` [rad]."""
        return wrap_angle(np.asarray(bearing, float) - self._pick("bearing_offset", robot))

    def range_of(self, reading: np.ndarray, bearing: np.ndarray, robot: int) -> np.ndarray:
        """Distance [m] from robot ``robot``'s centre of subjects its camera read as ``reading``
        [m] at the true ``bearing`` [rad]."""
        offset, scale = self.line(robot)
        return (np.asarray(reading, float) - offset) / (scale * np.cos(bearing))


@dataclass
class RobotLog:
    """One robot's logs: odometry (N, 3) t v ω; measurements (K, 4) t subject range bearing;
    ground truth (G, 4) t x y θ. Times in s."""

    odometry: np.ndarray
    measurements: np.ndarray
    groundtruth: np.ndarray


class MrclamDataset:
    """A MR.CLAM dataset folder, parsed.

    Attributes:
        robots: robot number -> RobotLog (measurement barcodes already mapped to subjects;
            unknown barcodes are dropped and counted in ``unknown_barcodes``).
        landmarks: (L, 3) subject, x [m], y [m] ground truth.
        num_robots: 5.
    """

    num_robots = 5

    def __init__(self, folder: str | Path):
        folder = Path(folder)
        if not folder.is_dir():
            raise DatasetError(f"not a folder: {folder}")
        barcodes = read_dat(folder / "Barcodes.dat", 2).astype(int)
        subject_of = {int(b): int(s) for s, b in barcodes}
        self.landmarks = read_dat(folder / "Landmark_Groundtruth.dat", 5)[:, :3]
        self.robots: dict[int, RobotLog] = {}
        self.unknown_barcodes = 0
        for i in range(1, self.num_robots + 1):
            meas = read_dat(folder / f"Robot{i}_Measurement.dat", 4)
            subj = np.array([subject_of.get(int(b), -1) for b in meas[:, 1]])
            self.unknown_barcodes += int((subj < 0).sum())
            meas = meas[subj >= 0].copy()
            meas[:, 1] = subj[subj >= 0]
            self.robots[i] = RobotLog(
                read_dat(folder / f"Robot{i}_Odometry.dat", 3),
                meas,
                read_dat(folder / f"Robot{i}_Groundtruth.dat", 4),
            )

    def calibrated(self, calibration: MrclamCalibration) -> MrclamDataset:
        """A copy whose measurements hold distances (:meth:`MrclamCalibration.range_of`) and
        whose odometry holds the executed velocities; ground truth and landmarks are shared."""
        out = copy.copy(self)
        out.robots = {}
        for i, log in self.robots.items():
            meas, odo = log.measurements.copy(), log.odometry.copy()
            meas[:, 3] = calibration.bearing_of(meas[:, 3], i)
            meas[:, 2] = calibration.range_of(meas[:, 2], meas[:, 3], i)
            odo[:, 1] *= calibration.velocity_scale
            odo[:, 2] *= calibration.turn_rate_scale
            out.robots[i] = replace(log, measurements=meas, odometry=odo)
        return out

    def time_span(self) -> tuple[float, float]:
        """Common ground-truth time span (start, end) [s] of all robots."""
        start = max(r.groundtruth[0, 0] for r in self.robots.values())
        end = min(r.groundtruth[-1, 0] for r in self.robots.values())
        return float(start), float(end)

    def groundtruth(self, robot: int, t: np.ndarray) -> np.ndarray:
        """Ground-truth poses (len(t), 3) of ``robot`` interpolated at times t [s]."""
        g = self.robots[robot].groundtruth
        return interpolate_poses(t, g[:, 0], g[:, 1:4])


class OdometryIntegrator:
    """Dead reckoning of one robot from (v, ω) samples, queried at any time.

    Each sample's velocities hold until the next sample (zero before the first). The pose is
    integrated exactly along arcs and stored at the sample times; queries interpolate between.
    ``delay`` [s] shifts the samples later (commanded velocities act after a latency).
    """

    def __init__(self, odometry: np.ndarray, delay: float = 0.0):
        odo = odometry[np.argsort(odometry[:, 0], kind="stable")]
        t, v, w = odo[:, 0] + delay, odo[:, 1], odo[:, 2]
        dt = np.diff(t, append=t[-1])
        th0 = np.concatenate([[0.0], np.cumsum(w * dt)[:-1]])
        # exact arc integration of constant (v, ω) over dt, starting at heading th0
        small = np.abs(w * dt) < 1e-9
        with np.errstate(divide="ignore", invalid="ignore"):
            dx = np.where(small, v * dt * np.cos(th0), v / w * (np.sin(th0 + w * dt) - np.sin(th0)))
            dy = np.where(small, v * dt * np.sin(th0), -v / w * (np.cos(th0 + w * dt) - np.cos(th0)))
        self.t = t
        # column-major: np.interp takes each column as it is instead of copying all N samples per query
        self.poses = np.asfortranarray(np.column_stack(
            [np.concatenate([[0.0], np.cumsum(dx)[:-1]]), np.concatenate([[0.0], np.cumsum(dy)[:-1]]), th0]
        ))

    def pose(self, t: np.ndarray | float) -> np.ndarray:
        """Odometry-frame pose(s) at t [s] (clamped to the log's span), (..., 3), θ unwrapped."""
        tq = np.atleast_1d(np.asarray(t, float))
        out = np.column_stack([np.interp(tq, self.t, self.poses[:, d]) for d in range(3)])
        return out if np.ndim(t) else out[0]

    def delta(self, t0: float, t1: float) -> np.ndarray:
        """Relative motion (3,) from t0 to t1 in the base frame at t0."""
        p = self.pose(np.array([t0, t1]))
        d = between(p[0], p[1])
        d[2] = wrap_angle(p[1, 2] - p[0, 2])
        return d

    def trajectory(self, start: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Dead-reckoned map-frame poses (len(t), 3) from ``start`` at t[0]."""
        p = self.pose(np.asarray(t, float))
        rel = between(p[:1], p)
        return compose(start, rel)
