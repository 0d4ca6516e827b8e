"""Public stereo datasets on disk: KITTI odometry and EuRoC/ASL sequence folders.

Both layouts are read into one value object, :class:`StereoSequence`: the calibrated stereo rig,
the image files of each stereo pair with its stamp, and (when the folder has it) the ground-truth
pose of the robot at every frame. Images are read lazily, one pair at a time (:meth:`StereoSequence.read`).

Frames (REP-103/105 style):

- **base_link** of a dataset is a camera-centred body frame at the left camera: x forward (the
  camera's viewing direction), y left, z up (the camera's "up"). It is level as far as the camera
  is level. ``t_base_cam`` (base_link <- left camera optical frame; optical: x right, y down,
  z forward) is the rotation :data:`T_BASE_CAM` (rows [0 0 1], [-1 0 0], [0 -1 0]) with zero
  translation, for both formats, so the frontend's observations come out x forward, y left, z up.
- **map** is base_link at the sequence's first frame: ``ground_truth[0]`` is the identity and
  ``ground_truth[i] = inv(T_world_base_0) · T_world_base_i`` with
  ``T_world_base = T_world_cam · inv(t_base_cam)``.

KITTI odometry (Geiger, Lenz, Urtasun, CVPR 2012), ``PATH`` is the sequence folder:

- ``image_0/`` and ``image_1/`` (or ``image_l/`` and ``image_r/``): rectified grey PNGs, paired by
  sorted file name;
- ``calib.txt``: ``P0: 12 numbers`` and ``P1: 12 numbers`` (row-major 3 × 4 projections of the
  rectified left and right cameras; ``P1[0, 3] = −f·b``), or just two unlabelled lines P0, P1;
- ``times.txt`` (optional): one time [s] per frame; without it frame i is at i × 0.1 s;
- ``poses.txt`` (optional): one row-major 3 × 4 ``[R | t]`` per frame, T_world_cam0, where the
  world is the first camera's optical frame (y down).

EuRoC MAV / ASL (Burri et al., IJRR 2016), ``PATH`` is the sequence root holding ``mav0/``,
``mav0/`` itself, or any folder holding ``cam0/`` and ``cam1/``:

- ``cam{0,1}/sensor.yaml``: intrinsics, radial-tangential distortion, T_BS (body <- camera);
- ``cam{0,1}/data/<stamp_ns>.png`` (full dataset) or ``cam{0,1}/<stamp_ns>.png`` (the project's
  micro sample); the stamp [ns] is the file name (``data.csv`` is not needed);
- ``state_groundtruth_estimate0/data.csv`` (optional, beside ``cam0/``): ``#timestamp [ns],
  p_RS_R_x, p_RS_R_y, p_RS_R_z [m], q_RS_w, q_RS_x, q_RS_y, q_RS_z, ...``: T_world_body with
  body = IMU. ``T_world_cam0 = T_world_body · T_BS(cam0)``; positions are interpolated linearly
  and rotations by slerp at the frame stamps.

EuRoC ground truth that starts after the first frame or ends before the last one: frames outside
its time span are DROPPED (the map frame is the ground truth at the first frame, so it must exist
there), and :attr:`StereoSequence.notes` says how many. When it covers no frame at all the
sequence keeps every frame and has no ground truth (also noted). A frame between two
ground-truth samples more than :data:`MAX_GT_GAP_NS` apart is an error (no interpolation over gaps).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from mrslam_core.datasets.mrclam import DatasetError
from mrslam_core.datasets.synthetic import R_BASE_OPTICAL
from mrslam_core.frontend.camera import CameraCalibration, StereoRig, load_euroc_stereo
from mrslam_core.frontend.errors import CameraModelError
from mrslam_core.frontend.frontend import image_to_grey
from mrslam_core.geometry.se2 import planar_from_matrix

__all__ = [
    "FORMATS", "KITTI_PERIOD_NS", "MAX_GT_GAP_NS", "T_BASE_CAM", "DatasetError", "StereoFrameFiles",
    "StereoSequence", "open_euroc", "open_kitti", "open_sequence", "rig_t_base_cam",
]

#: base_link (x forward, y left, z up) <- left camera optical frame (x right, y down, z forward),
#: zero translation: the body frame of every dataset sequence. (4, 4).
T_BASE_CAM = np.eye(4)
T_BASE_CAM[:3, :3] = R_BASE_OPTICAL
T_BASE_CAM.setflags(write=False)

#: Frame period of a KITTI sequence without ``times.txt`` [ns] (10 Hz).
KITTI_PERIOD_NS = 100_000_000

#: Largest gap between two EuRoC ground-truth samples a frame may be interpolated across [ns].
MAX_GT_GAP_NS = 100_000_000

#: The layouts :func:`open_sequence` reads.
FORMATS = ("kitti", "euroc")

_KITTI_IMAGE_DIRS = (("image_0", "image_1"), ("image_l", "image_r"))


@dataclass(frozen=True)
class StereoFrameFiles:
    """The two image files of one stereo pair.

    Attributes:
        left: left camera image (PNG).
        right: right camera image (PNG).
        stamp_ns: capture time [ns].
    """

    left: Path
    right: Path
    stamp_ns: int


@dataclass(frozen=True, eq=False)
class StereoSequence:
    """One stereo sequence of a public dataset: rig, image files and ground truth.

    Attributes:
        name: sequence name (the folder's name; ``<name>_<j>of<k>`` for a segment of :meth:`split`).
        format: ``"kitti"`` or ``"euroc"``.
        rig: the stereo rig; its extrinsic is :data:`T_BASE_CAM` (see the module docstring).
        frames: (N,) stereo pairs in strictly increasing stamp order.
        ground_truth: (N, 4, 4) map <- base_link pose at each frame [m], read-only, or None.
            ``ground_truth[0]`` is the identity for a whole sequence (not for a segment).
        notes: what the reader left out and why (unpaired images, frames outside the ground
            truth), one sentence each; empty when nothing was left out.
    """

    name: str
    format: str
    rig: StereoRig
    frames: tuple[StereoFrameFiles, ...]
    ground_truth: np.ndarray | None = None
    notes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.format not in FORMATS:
            raise DatasetError(f"sequence {self.name}: unknown format {self.format!r} (expected one of {FORMATS})")
        if not self.frames:
            raise DatasetError(f"sequence {self.name} has no frames")
        stamps = np.array([f.stamp_ns for f in self.frames], np.int64)
        if np.any(np.diff(stamps) <= 0):
            raise DatasetError(f"sequence {self.name}: frame stamps are not strictly increasing")
        if self.ground_truth is not None:
            gt = np.array(self.ground_truth, dtype=float)
            if gt.shape != (len(self.frames), 4, 4) or not np.isfinite(gt).all():
                raise DatasetError(f"sequence {self.name}: ground truth must be finite ({len(self.frames)}, 4, 4), "
                                   f"got shape {gt.shape}")
            gt.setflags(write=False)
            object.__setattr__(self, "ground_truth", gt)

    def __len__(self) -> int:
        return len(self.frames)

    @property
    def stamps_ns(self) -> np.ndarray:
        """(N,) frame stamps [ns], int64."""
        return np.array([f.stamp_ns for f in self.frames], np.int64)

    def read(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """The i-th stereo pair as grey images.

        Colour images are converted to grey, 16-bit ones keep their 8 most significant bits.

        Returns:
            (left, right): (H, W) uint8 each, H × W the rig's size [px].

        Raises:
            DatasetError: naming the file that is missing, not a readable image, of an unsupported
                pixel type, or not of the rig's size.
            IndexError: i out of range.
        """
        frame = self.frames[i]
        return self._read_grey(frame.left), self._read_grey(frame.right)

    def _read_grey(self, path: Path) -> np.ndarray:
        image = _read_image(path)
        if image.shape[:2] != (self.rig.height, self.rig.width):
            raise DatasetError(f"{path}: image is {image.shape[1]}x{image.shape[0]} px, the calibration says "
                               f"{self.rig.width}x{self.rig.height}")
        return image

    def planar_ground_truth(self) -> np.ndarray | None:
        """Ground truth in the plane of the map: (N, 3) x [m], y [m], yaw [rad] = atan2(R10, R00), or None."""
        if self.ground_truth is None:
            return None
        gt = self.ground_truth
        return planar_from_matrix(gt)

    def split(self, k: int) -> list[StereoSequence]:
        """Cut the sequence into k consecutive segments, as if k robots drove them at the same time.

        Segment sizes differ by at most one frame (the first ones are longer). Each segment is
        re-timed so that it starts at this sequence's first stamp (its stamps keep their spacing).
        Ground truth stays in THIS sequence's map frame, so a segment's first ground-truth pose is
        its robot's known start pose.

        Args:
            k: number of segments, 1 <= k <= len(self).

        Returns:
            k sequences named ``<name>_<j>of<k>`` (j = 1..k); for k = 1, ``[self]``.

        Raises:
            DatasetError: k out of range.
        """
        n = len(self.frames)
        if not 1 <= int(k) <= n:
            raise DatasetError(f"cannot split the {n} frames of {self.name} into {k} segments (need 1 <= k <= {n})")
        k = int(k)
        if k == 1:
            return [self]
        t0 = self.frames[0].stamp_ns
        out = []
        for j, idx in enumerate(np.array_split(np.arange(n), k)):
            shift = self.frames[idx[0]].stamp_ns - t0
            frames = tuple(dataclasses.replace(self.frames[i], stamp_ns=self.frames[i].stamp_ns - shift) for i in idx)
            gt = None if self.ground_truth is None else self.ground_truth[idx[0]:idx[-1] + 1]
            out.append(StereoSequence(f"{self.name}_{j + 1}of{k}", self.format, self.rig, frames, gt, self.notes))
        return out


def rig_t_base_cam(rig: StereoRig) -> np.ndarray:
    """(4, 4) base_link <- UNRECTIFIED left camera optical frame of ``rig`` (its ``t_base_cam``).

    A :class:`StereoRig` keeps ``t_base_rect = t_base_cam · [Rᵀ | 0]`` with R the left camera's
    rectification rotation; this undoes that product.
    """
    rect = np.eye(4)
    rect[:3, :3] = rig.left.R
    return rig.t_base_rect @ rect


def open_sequence(fmt: str, path: str | Path) -> StereoSequence:
    """Read the stereo sequence in folder ``path``.

    Args:
        fmt: ``"kitti"`` (KITTI odometry sequence folder) or ``"euroc"`` (EuRoC/ASL layout).
        path: the folder (see the module docstring for what each layout holds).

    Raises:
        DatasetError: unknown format, a missing folder, a folder that is not of the layout, or
            missing or malformed files; the message names the file or folder.
    """
    readers = {"kitti": open_kitti, "euroc": open_euroc}
    if fmt not in readers:
        raise DatasetError(f"unknown dataset format {fmt!r} for {path} (expected one of {', '.join(FORMATS)})")
    return readers[fmt](path)


# ----------------------------------------------------------------------------- KITTI
def open_kitti(path: str | Path) -> StereoSequence:
    """A KITTI odometry sequence folder (see the module docstring).

    Raises:
        DatasetError: no such folder, no image folders, missing calib.txt or P0/P1 in it, left and
            right image counts or names that differ, times.txt or poses.txt whose row count is not
            the image count, malformed rows, or stamps that do not increase.
    """
    folder = _existing_folder(path)
    dirs = next(((folder / a, folder / b) for a, b in _KITTI_IMAGE_DIRS
                 if (folder / a).is_dir() and (folder / b).is_dir()), None)
    if dirs is None:
        raise DatasetError(f"{folder} is not a KITTI odometry sequence folder: expected image_0/ and image_1/ "
                           f"(or image_l/ and image_r/) and calib.txt in it")
    left, right = (sorted(d.glob("*.png")) for d in dirs)
    if not left:
        raise DatasetError(f"{dirs[0]} holds no PNG images")
    if len(left) != len(right):
        raise DatasetError(f"{dirs[0]} has {len(left)} images but {dirs[1]} has {len(right)}")
    for a, b in zip(left, right):
        if a.name != b.name:
            raise DatasetError(f"{dirs[0]} and {dirs[1]} hold different file names ({a.name} vs {b.name})")
    n = len(left)
    p0, p1 = _kitti_projections(folder / "calib.txt")
    width, height = _image_size(left[0])
    try:
        rig = StereoRig(CameraCalibration(width, height, p0[:, :3], np.zeros(5), np.eye(3), p0),
                        CameraCalibration(width, height, p1[:, :3], np.zeros(5), np.eye(3), p1), T_BASE_CAM)
    except CameraModelError as exc:
        raise DatasetError(f"{folder / 'calib.txt'}: {exc}") from exc

    times = folder / "times.txt"
    if times.is_file():
        t = _numeric_table(times, 1, rows=n)[:, 0]
        stamps = np.round(t * 1e9).astype(np.int64)
        if np.any(np.diff(stamps) <= 0):
            raise DatasetError(f"{times}: times do not strictly increase")
    else:
        stamps = np.arange(n, dtype=np.int64) * KITTI_PERIOD_NS

    gt = None
    poses = folder / "poses.txt"
    if poses.is_file():
        rows = _numeric_table(poses, 12, rows=n)
        t_world_cam = np.tile(np.eye(4), (n, 1, 1))
        t_world_cam[:, :3, :] = rows.reshape(n, 3, 4)
        gt = _map_frame(t_world_cam)
    frames = tuple(StereoFrameFiles(a, b, int(s)) for a, b, s in zip(left, right, stamps))
    return StereoSequence(folder.name, "kitti", rig, frames, gt)


def _kitti_projections(calib: Path) -> tuple[np.ndarray, np.ndarray]:
    """P0 and P1 (3, 4) of a KITTI calib.txt: labelled ``P0: ...`` lines or two unlabelled lines."""
    if not calib.is_file():
        raise DatasetError(f"missing calibration file {calib}")
    labelled: dict[str, np.ndarray] = {}
    unlabelled: list[np.ndarray] = []
    for number, line in enumerate(calib.read_text().splitlines(), start=1):
        if not line.strip():
            continue
        label, _, values = line.rpartition(":")
        try:
            row = np.array(values.split(), dtype=float)
        except ValueError as exc:
            raise DatasetError(f"{calib}, line {number}: not numbers: {exc}") from exc
        if label:
            labelled[label.strip()] = row
        else:
            unlabelled.append(row)
    if labelled:
        found = [labelled.get("P0"), labelled.get("P1")]
    else:
        found = unlabelled[:2] + [None] * (2 - len(unlabelled[:2]))
    out = []
    for name, row in zip(("P0", "P1"), found):
        if row is None:
            raise DatasetError(f"{calib}: no {name} (expected lines 'P0: 12 numbers' and 'P1: 12 numbers', "
                               f"or two unlabelled lines of 12 numbers)")
        if row.size != 12 or not np.isfinite(row).all():
            raise DatasetError(f"{calib}: {name} has {row.size} values, expected 12 finite numbers")
        out.append(row.reshape(3, 4))
    return out[0], out[1]


# ----------------------------------------------------------------------------- EuRoC
def open_euroc(path: str | Path) -> StereoSequence:
    """A EuRoC/ASL sequence: the root holding ``mav0/``, ``mav0/`` itself, or a folder with
    ``cam0/`` and ``cam1/`` (see the module docstring).

    Left and right images are paired by identical stamps; images without a partner are dropped
    and counted in :attr:`StereoSequence.notes`.

    Raises:
        DatasetError: no such folder, not the layout, missing or malformed sensor.yaml, an image
            whose name is not a stamp, no stamp in both cameras, or malformed ground truth.
    """
    folder = _existing_folder(path)
    base = folder / "mav0" if (folder / "mav0").is_dir() else folder
    if not ((base / "cam0").is_dir() and (base / "cam1").is_dir()):
        raise DatasetError(f"{folder} is not a EuRoC/ASL sequence folder: expected mav0/, or cam0/ and cam1/ in it")
    for cam in ("cam0", "cam1"):
        if not (base / cam / "sensor.yaml").is_file():
            raise DatasetError(f"missing calibration file {base / cam / 'sensor.yaml'}")
    try:
        raw_rig = load_euroc_stereo(base)
        rig = StereoRig(raw_rig.left, raw_rig.right, T_BASE_CAM)
    except CameraModelError as exc:
        raise DatasetError(f"{base / 'cam0'}, {base / 'cam1'}: {exc}") from exc
    t_body_cam0 = rig_t_base_cam(raw_rig)  # T_BS of cam0

    left, right = _euroc_images(base / "cam0"), _euroc_images(base / "cam1")
    common = sorted(left.keys() & right.keys())
    if not common:
        raise DatasetError(f"{base / 'cam0'} ({len(left)} images) and {base / 'cam1'} ({len(right)} images) "
                           f"share no stamp: no stereo pair")
    notes = []
    for cam, images in (("cam0", left), ("cam1", right)):
        if len(images) > len(common):
            notes.append(f"dropped {len(images) - len(common)} of the {len(images)} images of {base / cam}: "
                         f"the other camera has no image with its stamp")
    frames = tuple(StereoFrameFiles(left[s], right[s], s) for s in common)

    gt = None
    gt_csv = base / "state_groundtruth_estimate0" / "data.csv"
    if gt_csv.is_file():
        first, t_world_cam = _euroc_ground_truth(gt_csv, np.array(common, np.int64), t_body_cam0)
        if t_world_cam is None:
            notes.append(f"{gt_csv} covers none of the {len(frames)} frames: no ground truth")
        else:
            kept = frames[first:first + len(t_world_cam)]
            if len(kept) < len(frames):
                notes.append(f"{len(frames) - len(kept)} frames outside the time span of {gt_csv} were dropped "
                             f"({first} at the start)")
            frames, gt = kept, _map_frame(t_world_cam)
    name = folder.parent.name if folder.name == "mav0" else folder.name
    return StereoSequence(name, "euroc", rig, frames, gt, tuple(notes))


def _euroc_images(cam: Path) -> dict[int, Path]:
    """Stamp [ns] -> PNG of one EuRoC camera folder (``data/`` inside it, or the folder itself)."""
    folder = cam / "data" if (cam / "data").is_dir() else cam
    images = {}
    for png in folder.glob("*.png"):
        try:
            images[int(png.stem)] = png
        except ValueError:
            raise DatasetError(f"{png}: EuRoC image names must be stamps in ns") from None
    if not images:
        raise DatasetError(f"{folder} holds no PNG images")
    return images


def _euroc_ground_truth(csv: Path, stamps: np.ndarray, t_body_cam: np.ndarray) -> tuple[int, np.ndarray | None]:
    """Ground truth of the frames inside the csv's time span.

    Args:
        csv: ``state_groundtruth_estimate0/data.csv``.
        stamps: (N,) increasing frame stamps [ns].
        t_body_cam: (4, 4) T_BS of cam0.

    Returns:
        (index of the first covered frame, (M, 4, 4) T_world_cam0 of the M covered frames), or
        (0, None) when no frame is covered.
    """
    from scipy.spatial.transform import Rotation, Slerp

    try:
        t = np.loadtxt(csv, delimiter=",", comments="#", usecols=0, dtype=np.int64, ndmin=1)
        table = np.loadtxt(csv, delimiter=",", comments="#", usecols=range(1, 8), ndmin=2)
    except (ValueError, IndexError) as exc:
        raise DatasetError(f"{csv}: malformed rows (expected #timestamp, p_x, p_y, p_z, q_w, q_x, q_y, q_z, ...): "
                           f"{exc}") from exc
    if len(t) < 2 or np.any(np.diff(t) <= 0) or not np.isfinite(table).all():
        raise DatasetError(f"{csv}: needs at least 2 rows of finite values with strictly increasing stamps")
    covered = np.flatnonzero((stamps >= t[0]) & (stamps <= t[-1]))
    if covered.size == 0:
        return 0, None
    s = stamps[covered]
    hi = np.minimum(np.searchsorted(t, s), len(t) - 1)
    gap = np.where(t[hi] == s, 0, t[hi] - t[np.maximum(hi - 1, 0)])
    if gap.max() > MAX_GT_GAP_NS:
        bad = int(s[np.argmax(gap)])
        raise DatasetError(f"{csv}: a gap of {gap.max() * 1e-9:.3f} s around frame {bad} ns "
                           f"(interpolating over more than {MAX_GT_GAP_NS * 1e-9:.3f} s is refused)")
    rel = (t - t[0]) * 1e-9
    q = Rotation.from_quat(table[:, [4, 5, 6, 3]])  # x y z w
    t_world_body = np.tile(np.eye(4), (len(s), 1, 1))
    t_world_body[:, :3, :3] = Slerp(rel, q)((s - t[0]) * 1e-9).as_matrix()
    for axis in range(3):
        t_world_body[:, axis, 3] = np.interp((s - t[0]) * 1e-9, rel, table[:, axis])
    return int(covered[0]), t_world_body @ t_body_cam


# ----------------------------------------------------------------------------- helpers
def _existing_folder(path: str | Path) -> Path:
    folder = Path(path)
    if not folder.is_dir():
        raise DatasetError(f"no such folder {folder}")
    return folder


def _numeric_table(path: Path, columns: int, rows: int) -> np.ndarray:
    """Whitespace-separated numbers, shape (rows, columns), finite; DatasetError naming ``path``."""
    try:
        data = np.loadtxt(path, ndmin=2)
    except ValueError as exc:
        raise DatasetError(f"{path}: malformed rows: {exc}") from exc
    if data.shape != (rows, columns):
        raise DatasetError(f"{path}: expected {rows} rows (one per image) of {columns} numbers, "
                           f"found {data.shape[0]} rows of {data.shape[1] if data.size else 0}")
    if not np.isfinite(data).all():
        raise DatasetError(f"{path}: non-finite values")
    return data


def _read_image(path: Path) -> np.ndarray:
    """A grey (H, W) uint8 image from a file; DatasetError naming the file."""
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise DatasetError(f"{path}: missing, or not a readable image")
    grey, reason = image_to_grey(image, None)
    if grey is None:
        raise DatasetError(f"{path}: unsupported image ({reason}: {image.dtype}, shape {image.shape})")
    return grey


def _image_size(path: Path) -> tuple[int, int]:
    """(width, height) [px] of an image file."""
    image = _read_image(path)
    return int(image.shape[1]), int(image.shape[0])


def _rigid_inverse(t: np.ndarray) -> np.ndarray:
    """Inverse of rigid transforms (..., 4, 4): [Rᵀ | −Rᵀ·t]."""
    out = np.zeros_like(t)
    rt = np.swapaxes(t[..., :3, :3], -1, -2)
    out[..., :3, :3] = rt
    out[..., :3, 3] = -(rt @ t[..., :3, 3:4])[..., 0]
    out[..., 3, 3] = 1.0
    return out


def _map_frame(t_world_cam: np.ndarray) -> np.ndarray:
    """(N, 4, 4) T_world_cam (left optical) -> (N, 4, 4) map <- base_link, map = base_link at frame 0."""
    t_world_base = t_world_cam @ _rigid_inverse(T_BASE_CAM)
    return _rigid_inverse(t_world_base[0]) @ t_world_base
