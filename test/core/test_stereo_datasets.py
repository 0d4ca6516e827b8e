"""KITTI odometry and EuRoC/ASL stereo sequence readers.

Tiny synthetic layouts are written into tmp_path with exact expected answers; the real excerpts in
../shared/data are read when present.

Frames: camera optical X right, Y down, Z forward; base_link and map X forward, Y left, Z up.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mrslam_core.datasets.stereo import (
    KITTI_PERIOD_NS,
    T_BASE_CAM,
    DatasetError,
    StereoSequence,
    open_sequence,
    rig_t_base_cam,
)

W, H = 40, 24  # image size [px]
F, CX, CY = 50.0, 20.0, 12.0  # rectified intrinsics [px]
B_KITTI, B_EUROC = 0.5, 0.1  # baselines [m]
T0 = 1_403_715_273_000_000_000  # first EuRoC stamp [ns]


def _pixels(i: int, side: int) -> np.ndarray:
    return np.random.default_rng([abs(i), side, i < 0]).integers(0, 256, (H, W), dtype=np.uint8)


def _rt(rot: np.ndarray = np.eye(3), t=(0.0, 0.0, 0.0)) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rot, t
    return out


def _roty(a: float) -> np.ndarray:
    """Rotation about the camera's y (down) axis: z (forward) turns towards +x (right) for a > 0."""
    return Rotation.from_euler("y", a).as_matrix()


# camera poses in the KITTI world (= first camera frame, y down); frame 0 is not the identity so the
# map frame must be taken relative to it
KITTI_POSES = [
    _rt(_roty(0.5), (5.0, 0.0, 0.0)),
    _rt(_roty(0.5), (5.0, 0.0, 0.0)) @ _rt(t=(0.0, 0.0, 1.0)),     # 1 m forward
    _rt(_roty(0.5), (5.0, 0.0, 0.0)) @ _rt(t=(0.5, 0.2, 2.0)),     # 2 m forward, 0.5 m right, 0.2 m down
    _rt(_roty(0.5), (5.0, 0.0, 0.0)) @ _rt(_roty(0.3)),            # turned right by 0.3 rad
    _rt(_roty(0.5), (5.0, 0.0, 0.0)) @ _rt(_roty(-0.2), (0.0, 0.0, 4.0)),
]


def write_kitti(root: Path, n: int = 5, labelled: bool = True, times: list[float] | None = None,
                poses: bool = True, dirs: tuple[str, str] = ("image_0", "image_1")) -> Path:
    """A KITTI odometry sequence folder of n W×H frames; pixels from :func:`_pixels`."""
    root.mkdir(parents=True, exist_ok=True)
    for side, d in enumerate(dirs):
        (root / d).mkdir(exist_ok=True)
        for i in range(n):
            cv2.imwrite(str(root / d / f"{i:06d}.png"), _pixels(i, side))
    p0 = np.array([[F, 0, CX, 0], [0, F, CY, 0], [0, 0, 1, 0]])
    p1 = p0.copy()
    p1[0, 3] = -F * B_KITTI
    rows = [" ".join(f"{v:.12e}" for v in p.ravel()) for p in (p0, p1)]
    if labelled:
        rows = [f"P0: {rows[0]}", f"P1: {rows[1]}", f"P2: {rows[0]}", "Tr: " + " ".join(["0"] * 12)]
    (root / "calib.txt").write_text("\n".join(rows) + "\n")
    if times is not None:
        (root / "times.txt").write_text("".join(f"{t:.6e}\n" for t in times))
    if poses:
        (root / "poses.txt").write_text("".join(" ".join(f"{v:.12e}" for v in p[:3].ravel()) + "\n"
                                                for p in KITTI_POSES[:n]))
    return root


def _sensor_yaml(path: Path, t_bs: np.ndarray) -> None:
    """A cam sensor.yaml laid out like EuRoC's (OpenCV's %YAML:1.0 header, T_BS rows/cols/data)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    data = ", ".join(f"{v:.15g}" for v in t_bs.ravel())
    path.write_text(f"""%YAML:1.0
# General sensor definitions.
sensor_type: camera
comment: synthetic

# Sensor extrinsics wrt. the body-frame.
T_BS:
  cols: 4
  rows: 4
  data: [{data}]

rate_hz: 20
resolution: [{W}, {H}]
camera_model: pinhole
intrinsics: [{F}, {F}, {CX}, {CY}] #fu, fv, cu, cv
distortion_model: radial-tangential
distortion_coefficients: [0.0, 0.0, 0.0, 0.0]
""")


# cam0 0.1 m ahead of the IMU, looking along the body's x: body = base_link shifted by 0.1 m
T_BS0 = _rt(T_BASE_CAM[:3, :3], (0.1, 0.0, 0.0))
T_BS1 = T_BS0 @ _rt(t=(B_EUROC, 0.0, 0.0))  # cam1 0.1 m to the right of cam0


def write_euroc(root: Path, left_ms: list[int], right_ms: list[int], nested: bool = True,
                gt_ms: list[int] | None = None) -> Path:
    """A EuRoC layout with images at T0 + ms; nested: root/mav0/camX/data/, else root/camX/.

    Ground truth (body = IMU in the world) at T0 + gt_ms: the body moves along world x at 1 m/s
    and turns left at π/2 rad/s, both from t = T0.
    """
    base = root / "mav0" if nested else root
    for side, (cam, t_bs, stamps) in enumerate((("cam0", T_BS0, left_ms), ("cam1", T_BS1, right_ms))):
        _sensor_yaml(base / cam / "sensor.yaml", t_bs)
        folder = base / cam / "data" if nested else base / cam
        folder.mkdir(parents=True, exist_ok=True)
        for ms in stamps:
            cv2.imwrite(str(folder / f"{T0 + ms * 1_000_000}.png"), _pixels(ms, side))
    if gt_ms is not None:
        rows = ["#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], "
                "v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1]"]
        for ms in gt_ms:
            s = ms / 1000.0
            x, y, z, w = Rotation.from_euler("z", np.pi / 2 * s).as_quat()
            rows.append(f"{T0 + ms * 1_000_000},{s:.9f},0.0,1.5,{w:.15f},{x:.15f},{y:.15f},{z:.15f},1.0,0.0,0.0")
        (base / "state_groundtruth_estimate0").mkdir(parents=True, exist_ok=True)
        (base / "state_groundtruth_estimate0" / "data.csv").write_text("\n".join(rows) + "\n")
    return root


def _expected_euroc_gt(ms: float, ms0: float) -> np.ndarray:
    """map <- base_link at T0 + ms, map = base_link at T0 + ms0 (see write_euroc)."""
    def t_world_base(m):
        s = m / 1000.0
        return _rt(Rotation.from_euler("z", np.pi / 2 * s).as_matrix(), (s, 0.0, 1.5)) @ _rt(t=(0.1, 0.0, 0.0))
    return np.linalg.inv(t_world_base(ms0)) @ t_world_base(ms)


# ----------------------------------------------------------------------------- KITTI
@pytest.mark.parametrize("labelled", [True, False])
def test_kitti_rig_stamps_and_images(tmp_path, labelled):
    seq = open_sequence("kitti", write_kitti(tmp_path / "00", labelled=labelled))
    assert (seq.name, seq.format, len(seq)) == ("00", "kitti", 5)
    rig = seq.rig
    assert (rig.width, rig.height) == (W, H)
    assert (rig.f, rig.cx, rig.cy) == (F, CX, CY)
    assert rig.baseline == pytest.approx(B_KITTI, abs=1e-12)
    assert not rig.needs_rectification
    np.testing.assert_array_equal(rig_t_base_cam(rig), T_BASE_CAM)
    np.testing.assert_array_equal(seq.stamps_ns, np.arange(5) * KITTI_PERIOD_NS)
    assert seq.frames[2].left.name == "000002.png" and seq.frames[2].left.parent.name == "image_0"
    left, right = seq.read(3)
    assert left.dtype == np.uint8 and left.shape == (H, W)
    np.testing.assert_array_equal(left, _pixels(3, 0))
    np.testing.assert_array_equal(right, _pixels(3, 1))
    assert seq.notes == ()


def test_kitti_times_and_lr_folders(tmp_path):
    seq = open_sequence("kitti", write_kitti(tmp_path / "s", n=3, times=[1.5, 1.6, 1.75], poses=False,
                                             dirs=("image_l", "image_r")))
    np.testing.assert_array_equal(seq.stamps_ns, [1_500_000_000, 1_600_000_000, 1_750_000_000])
    assert seq.ground_truth is None and seq.planar_ground_truth() is None
    assert seq.frames[0].right.parent.name == "image_r"


def test_kitti_ground_truth_in_the_map_frame(tmp_path):
    seq = open_sequence("kitti", write_kitti(tmp_path / "s"))
    gt = seq.ground_truth
    assert gt.shape == (5, 4, 4) and not gt.flags.writeable
    np.testing.assert_allclose(gt[0], np.eye(4), atol=1e-12)
    # 1 m along the camera's z is 1 m forward (x) in base_link / map
    np.testing.assert_allclose(gt[1], _rt(t=(1.0, 0.0, 0.0)), atol=1e-12)
    # camera x (right) is -y, camera y (down) is -z
    np.testing.assert_allclose(gt[2], _rt(t=(2.0, -0.5, -0.2)), atol=1e-12)
    # a turn to the right (about the camera's y, down) is a negative yaw
    planar = seq.planar_ground_truth()
    np.testing.assert_allclose(planar, [[0, 0, 0], [1, 0, 0], [2, -0.5, 0], [0, 0, -0.3], [4, 0, 0.2]], atol=1e-12)
    np.testing.assert_allclose(gt[3][:3, :3], Rotation.from_euler("z", -0.3).as_matrix(), atol=1e-12)


def test_split_retimes_and_keeps_the_map_frame(tmp_path):
    seq = open_sequence("kitti", write_kitti(tmp_path / "s", times=[2.0, 2.1, 2.2, 2.3, 2.4]))
    parts = seq.split(2)
    assert [p.name for p in parts] == ["s_1of2", "s_2of2"]
    assert [len(p) for p in parts] == [3, 2]
    np.testing.assert_array_equal(parts[0].stamps_ns, [2_000_000_000, 2_100_000_000, 2_200_000_000])
    np.testing.assert_array_equal(parts[1].stamps_ns, [2_000_000_000, 2_100_000_000])
    assert parts[1].frames[0].left == seq.frames[3].left
    np.testing.assert_array_equal(parts[1].ground_truth, seq.ground_truth[3:])
    np.testing.assert_allclose(parts[1].planar_ground_truth()[0], [0.0, 0.0, -0.3], atol=1e-12)
    assert parts[0].rig is seq.rig
    assert [len(p) for p in seq.split(5)] == [1] * 5
    assert seq.split(1) == [seq]
    for k in (0, 6):
        with pytest.raises(DatasetError, match=f"into {k} segments"):
            seq.split(k)


def test_kitti_errors_name_the_file(tmp_path):
    root = write_kitti(tmp_path / "s")
    (root / "calib.txt").unlink()
    with pytest.raises(DatasetError, match=r"missing calibration file .*s/calib\.txt"):
        open_sequence("kitti", root)

    root = write_kitti(tmp_path / "p1")
    (root / "calib.txt").write_text((root / "calib.txt").read_text().replace("P1:", "P9:"))
    with pytest.raises(DatasetError, match=r"p1/calib\.txt: no P1"):
        open_sequence("kitti", root)

    root = write_kitti(tmp_path / "short")
    (root / "calib.txt").write_text("P0: 1 2 3\nP1: 1 2 3\n")
    with pytest.raises(DatasetError, match=r"short/calib\.txt: P0 has 3 values"):
        open_sequence("kitti", root)

    root = write_kitti(tmp_path / "count")
    (root / "image_1" / "000004.png").unlink()
    with pytest.raises(DatasetError, match=r"count/image_0 has 5 images but .*count/image_1 has 4"):
        open_sequence("kitti", root)

    root = write_kitti(tmp_path / "times", times=[0.0, 0.1, 0.2])
    with pytest.raises(DatasetError, match=r"times/times\.txt: expected 5 rows"):
        open_sequence("kitti", root)

    root = write_kitti(tmp_path / "poses")
    with (root / "poses.txt").open("a") as f:
        f.write("1 0 0 0 0 1 0 0 0 0 1 x\n")
    with pytest.raises(DatasetError, match=r"poses/poses\.txt: malformed rows"):
        open_sequence("kitti", root)

    root = write_kitti(tmp_path / "poses12", n=2)
    (root / "poses.txt").write_text("1 0 0 0 0 1 0 0 0 0 1\n1 0 0 0 0 1 0 0 0 0 1\n")
    with pytest.raises(DatasetError, match=r"poses12/poses\.txt: expected 2 rows .* of 12 numbers"):
        open_sequence("kitti", root)


def test_bad_images_fail_on_read_naming_the_file(tmp_path):
    root = write_kitti(tmp_path / "s")
    cv2.imwrite(str(root / "image_1" / "000002.png"), np.zeros((H, W + 2), np.uint8))
    (root / "image_0" / "000003.png").write_bytes(b"\x89PNG\r\n\x1a\n not really a png")
    seq = open_sequence("kitti", root)  # lazy: opening does not read these
    with pytest.raises(DatasetError, match=r"image_1/000002\.png: image is 42x24 px, the calibration says 40x24"):
        seq.read(2)
    with pytest.raises(DatasetError, match=r"image_0/000003\.png: missing, or not a readable image"):
        seq.read(3)
    left, _ = seq.read(4)
    assert left.shape == (H, W)


def test_colour_and_16_bit_images_become_grey_uint8(tmp_path):
    root = write_kitti(tmp_path / "s", n=2)
    cv2.imwrite(str(root / "image_0" / "000001.png"), np.full((H, W), 0x1234, np.uint16))
    cv2.imwrite(str(root / "image_1" / "000001.png"), np.dstack([np.full((H, W), 200, np.uint8)] * 3))
    left, right = open_sequence("kitti", root).read(1)
    assert left.dtype == right.dtype == np.uint8
    assert (left == 0x12).all() and (right == 200).all()


def test_unknown_format_or_layout(tmp_path):
    kitti = write_kitti(tmp_path / "k")
    (tmp_path / "empty").mkdir()
    with pytest.raises(DatasetError, match=r"unknown dataset format 'tum' for .*k \(expected one of kitti, euroc\)"):
        open_sequence("tum", kitti)
    with pytest.raises(DatasetError, match=r"empty is not a KITTI odometry sequence folder: expected image_0/"):
        open_sequence("kitti", tmp_path / "empty")
    with pytest.raises(DatasetError, match=r"k is not a EuRoC/ASL sequence folder: expected mav0/, or cam0/ and cam1/"):
        open_sequence("euroc", kitti)
    with pytest.raises(DatasetError, match=r"no such folder .*nowhere"):
        open_sequence("kitti", tmp_path / "nowhere")
    (tmp_path / "noimg" / "image_0").mkdir(parents=True)
    (tmp_path / "noimg" / "image_1").mkdir()
    with pytest.raises(DatasetError, match=r"noimg/image_0 holds no PNG images"):
        open_sequence("kitti", tmp_path / "noimg")


# ----------------------------------------------------------------------------- EuRoC
@pytest.mark.parametrize("nested", [True, False])
def test_euroc_layouts_rig_and_pairing(tmp_path, nested):
    root = write_euroc(tmp_path / "V9", left_ms=[0, 50, 100, 150, 200], right_ms=[0, 50, 150, 200, 250, 300],
                       nested=nested)
    paths = [root, root / "mav0"] if nested else [root]
    for path in paths:
        seq = open_sequence("euroc", path)
        assert (seq.name, seq.format, len(seq)) == ("V9", "euroc", 4)
        np.testing.assert_array_equal(seq.stamps_ns - T0, np.array([0, 50, 150, 200]) * 1_000_000)
        base = root / "mav0" if nested else root
        assert seq.notes == (
            f"dropped 1 of the 5 images of {base / 'cam0'}: the other camera has no image with its stamp",
            f"dropped 2 of the 6 images of {base / 'cam1'}: the other camera has no image with its stamp",
        )
        rig = seq.rig
        assert (rig.width, rig.height) == (W, H)
        assert (rig.f, rig.cx, rig.cy) == pytest.approx((F, CX, CY), abs=1e-9)
        assert rig.baseline == pytest.approx(B_EUROC, abs=1e-12)
        np.testing.assert_allclose(rig_t_base_cam(rig), T_BASE_CAM, atol=1e-12)  # not T_BS
        assert seq.ground_truth is None
        left, right = seq.read(2)  # the pair at 150 ms
        np.testing.assert_array_equal(left, _pixels(150, 0))
        np.testing.assert_array_equal(right, _pixels(150, 1))


def test_euroc_ground_truth_interpolated_in_the_map_frame(tmp_path):
    # ground truth every 100 ms from 0 to 1000 ms; frames every 50 ms from -100 to 1100 ms
    frames = list(range(-100, 1101, 50))
    root = write_euroc(tmp_path / "MH", frames, frames, gt_ms=list(range(0, 1001, 100)))
    seq = open_sequence("euroc", root)
    # frames before the first and after the last ground-truth sample are dropped
    np.testing.assert_array_equal(seq.stamps_ns - T0, np.arange(0, 1001, 50) * 1_000_000)
    assert seq.notes == (f"4 frames outside the time span of {root / 'mav0/state_groundtruth_estimate0/data.csv'} "
                         "were dropped (2 at the start)",)
    gt = seq.ground_truth
    np.testing.assert_allclose(gt[0], np.eye(4), atol=1e-12)
    for i, ms in enumerate(range(0, 1001, 50)):  # odd i: half-way between samples (linear + slerp)
        np.testing.assert_allclose(gt[i], _expected_euroc_gt(ms, 0), atol=1e-9)
    # at 1 s the body has turned left by π/2 about the IMU, 0.1 m behind the camera
    np.testing.assert_allclose(seq.planar_ground_truth()[-1], [1.0 - 0.1, 0.1, np.pi / 2], atol=1e-9)
    part = seq.split(2)[1]
    np.testing.assert_allclose(part.ground_truth[0], _expected_euroc_gt(550, 0), atol=1e-9)
    assert part.stamps_ns[0] == T0


def test_euroc_ground_truth_that_covers_no_frame(tmp_path):
    root = write_euroc(tmp_path / "s", [0, 50], [0, 50], gt_ms=[500, 600])
    seq = open_sequence("euroc", root)
    assert len(seq) == 2 and seq.ground_truth is None
    assert seq.notes == (f"{root / 'mav0/state_groundtruth_estimate0/data.csv'} covers none of the 2 frames: "
                         "no ground truth",)


def test_euroc_errors_name_the_file(tmp_path):
    root = write_euroc(tmp_path / "gap", [0, 150], [0, 150], gt_ms=[0, 100, 300])
    with pytest.raises(DatasetError, match=r"gap/mav0/state_groundtruth_estimate0/data\.csv: a gap of 0\.200 s"):
        open_sequence("euroc", root)

    root = write_euroc(tmp_path / "bad", [0], [0], gt_ms=[0, 100])
    csv = root / "mav0/state_groundtruth_estimate0/data.csv"
    csv.write_text(csv.read_text() + "12,1,2\n")
    with pytest.raises(DatasetError, match=r"bad/mav0/state_groundtruth_estimate0/data\.csv: malformed rows"):
        open_sequence("euroc", root)

    root = write_euroc(tmp_path / "nopair", [0, 50], [20, 70])
    with pytest.raises(DatasetError, match=r"nopair/mav0/cam0 \(2 images\) and .*cam1 \(2 images\) share no stamp"):
        open_sequence("euroc", root)

    root = write_euroc(tmp_path / "nocal", [0], [0])
    (root / "mav0/cam1/sensor.yaml").unlink()
    with pytest.raises(DatasetError, match=r"missing calibration file .*nocal/mav0/cam1/sensor\.yaml"):
        open_sequence("euroc", root)

    root = write_euroc(tmp_path / "name", [0], [0])
    cv2.imwrite(str(root / "mav0/cam0/data/frame.png"), _pixels(0, 0))
    with pytest.raises(DatasetError, match=r"name/mav0/cam0/data/frame\.png: EuRoC image names must be stamps"):
        open_sequence("euroc", root)


def test_sequence_checks_its_fields(tmp_path):
    seq = open_sequence("kitti", write_kitti(tmp_path / "s", n=2))
    with pytest.raises(DatasetError, match="not strictly increasing"):
        StereoSequence("x", "kitti", seq.rig, seq.frames[::-1])
    with pytest.raises(DatasetError, match=r"ground truth must be finite \(2, 4, 4\)"):
        StereoSequence("x", "kitti", seq.rig, seq.frames, np.zeros((3, 4, 4)))
    with pytest.raises(DatasetError, match="unknown format"):
        StereoSequence("x", "tum", seq.rig, seq.frames)


# ----------------------------------------------------------------------------- real data
def test_real_kitti_excerpt(kitti_dir):
    seq = open_sequence("kitti", kitti_dir)
    assert len(seq) == 51 and (seq.rig.width, seq.rig.height) == (1226, 370)
    assert seq.rig.f == pytest.approx(707.0912)
    assert seq.rig.baseline == pytest.approx(0.537, abs=1e-3)
    assert seq.stamps_ns[-1] == 5_000_000_000
    planar = seq.planar_ground_truth()
    np.testing.assert_allclose(planar[0], 0.0, atol=1e-9)
    # the car drives about 60 m, nearly straight ahead (+x of the map), on level ground
    assert 55.0 < planar[-1, 0] < 65.0
    assert np.abs(planar[:, 1]).max() < 2.0 and np.abs(planar[:, 2]).max() < 0.1
    assert np.all(np.diff(planar[:, 0]) > 0)
    assert np.abs(seq.ground_truth[:, 2, 3]).max() < 2.0
    left, right = seq.read(50)
    assert left.shape == right.shape == (370, 1226) and left.dtype == np.uint8
    assert 40 < left.mean() < 200


def test_real_euroc_micro(euroc_micro):
    seq = open_sequence("euroc", euroc_micro)
    assert (seq.name, len(seq), seq.notes) == ("euroc_v101_micro", 30, ())
    assert (seq.rig.width, seq.rig.height) == (752, 480) and seq.rig.needs_rectification
    assert seq.stamps_ns[0] == 1403715273262142976
    assert seq.rig.baseline == pytest.approx(0.110, abs=1e-3)
    np.testing.assert_allclose(rig_t_base_cam(seq.rig), T_BASE_CAM, atol=1e-12)
    assert seq.ground_truth is None
    left, right = seq.read(29)
    assert left.shape == right.shape == (480, 752) and left.dtype == np.uint8
