"""Stereo dataset sequences written into rosbag2 (both storages) and read back; no running graph.

The bag must carry what the simulator publishes (topics, frames, CameraInfo the frontend node
turns back into the same calibration), so these read it with the project's own decoders.

Frames: camera optical X right, Y down, Z forward; base_link X forward, Y left, Z up.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from mrslam_core.datasets.stereo import T_BASE_CAM, open_sequence
from mrslam_ros.bag import BagError, bag_info, deserialize, read_bag
from mrslam_ros.conversions import camera_info_to_calibration, image_to_array, odometry_to_pose, stamp_to_ns
from mrslam_ros.dataset_bag import write_dataset_bag
from mrslam_ros.dataset_cli import import_main
from mrslam_ros.runlog import deserialize as deserialize_rclpy
from mrslam_ros.runlog import read_series

STORAGES = ["sqlite3", "mcap"]
N = 4  # frames of the tiny sequence, 10 Hz from 0 s (no times.txt)


@pytest.fixture
def kitti_tiny(tmp_path) -> Path:
    """A 4-frame 32×20 KITTI odometry folder: f 40 px, baseline 0.25 m, camera 1 m forward a frame."""
    root = tmp_path / "07"
    rng = np.random.default_rng(7)
    for d in ("image_0", "image_1"):
        (root / d).mkdir(parents=True)
        for i in range(N):
            cv2.imwrite(str(root / d / f"{i:06d}.png"), rng.integers(0, 256, (20, 32), dtype=np.uint8))
    (root / "calib.txt").write_text("P0: 40 0 16 0 0 40 10 0 0 0 1 0\nP1: 40 0 16 -10 0 40 10 0 0 0 1 0\n")
    (root / "poses.txt").write_text("".join(f"1 0 0 0 0 1 0 0 0 0 1 {i}\n" for i in range(N)))
    return root


def _tf_matrix(tr) -> np.ndarray:
    q = tr.transform.rotation
    out = np.eye(4)
    out[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    out[:3, 3] = [tr.transform.translation.x, tr.transform.translation.y, tr.transform.translation.z]
    return out


@pytest.mark.parametrize("storage", STORAGES)
def test_one_robot_bag(tmp_path, kitti_tiny, storage):
    seq = open_sequence("kitti", kitti_tiny)
    bag = write_dataset_bag([("robot1", seq)], tmp_path / "bag", storage=storage, progress=False)
    info = bag_info(bag)
    assert info.storage == storage
    assert {t: (i.msgtype, i.count) for t, i in info.topics.items()} == {
        "/robot1/stereo/left/image_raw": ("sensor_msgs/msg/Image", N),
        "/robot1/stereo/right/image_raw": ("sensor_msgs/msg/Image", N),
        "/robot1/stereo/left/camera_info": ("sensor_msgs/msg/CameraInfo", N),
        "/robot1/stereo/right/camera_info": ("sensor_msgs/msg/CameraInfo", N),
        "/robot1/ground_truth": ("nav_msgs/msg/Odometry", N),
        "/tf_static": ("tf2_msgs/msg/TFMessage", 1),
        "/clock": ("rosgraph_msgs/msg/Clock", N),
    }
    assert (info.start_ns, info.end_ns) == (0, (N - 1) * 100_000_000)

    msgs = list(read_bag(bag))
    assert msgs[0].topic == "/tf_static" and msgs[1].topic == "/clock"
    assert [m.stamp_ns for m in msgs] == sorted(m.stamp_ns for m in msgs)
    for m in msgs:
        if m.topic not in ("/tf_static", "/clock"):
            assert stamp_to_ns(deserialize(m.data, m.msgtype).header.stamp) == m.stamp_ns  # log time = stamp
    clocks = [stamp_to_ns(deserialize(m.data, m.msgtype).clock) for m in msgs if m.topic == "/clock"]
    assert clocks == [i * 100_000_000 for i in range(N)]

    # images: the PNG's pixels, mono8, in the optical frames the simulator uses
    for side, folder in (("left", "image_0"), ("right", "image_1")):
        images = [deserialize_rclpy(m.data, m.msgtype) for m in msgs if m.topic == f"/robot1/stereo/{side}/image_raw"]
        for i, img in enumerate(images):
            assert (img.encoding, img.header.frame_id) == ("mono8", f"robot1/camera_{side}_optical")
            np.testing.assert_array_equal(image_to_array(img),
                                          cv2.imread(str(kitti_tiny / folder / f"{i:06d}.png"), cv2.IMREAD_UNCHANGED))

    # tf_static: base_link -> left optical is the level camera frame; the right camera 0.25 m to its right
    tf = deserialize(msgs[0].data, msgs[0].msgtype).transforms
    assert [(t.header.frame_id, t.child_frame_id) for t in tf] == [
        ("robot1/base_link", "robot1/camera_left_optical"), ("robot1/base_link", "robot1/camera_right_optical")]
    np.testing.assert_allclose(_tf_matrix(tf[0]), T_BASE_CAM, atol=1e-12)
    right = T_BASE_CAM.copy()
    right[:3, 3] = [0.0, -0.25, 0.0]
    np.testing.assert_allclose(_tf_matrix(tf[1]), right, atol=1e-12)

    # ground truth: map -> base_link, 1 m forward (+x) per frame, read as the replay reads it
    truth = [deserialize_rclpy(m.data, m.msgtype) for m in msgs if m.topic == "/robot1/ground_truth"]
    assert {(t.header.frame_id, t.child_frame_id) for t in truth} == {("map", "robot1/base_link")}
    for i, t in enumerate(truth):
        stamp, pose, _ = odometry_to_pose(t)
        assert stamp == i * 100_000_000
        np.testing.assert_allclose(pose, [i, 0.0, 0.0], atol=1e-12)
    t_gt, gt = read_series(bag, ["robot1"], ["ground_truth"])["robot1"]["ground_truth"].arrays()
    np.testing.assert_array_equal(t_gt, np.arange(N) * 100_000_000)
    np.testing.assert_allclose(gt, seq.planar_ground_truth(), atol=1e-12)


@pytest.mark.parametrize("storage", STORAGES)
def test_camera_info_round_trip(tmp_path, kitti_tiny, storage):
    """CameraInfo of the bag -> conversions.camera_info_to_calibration is the rig's calibration, exactly."""
    seq = open_sequence("kitti", kitti_tiny)
    bag = write_dataset_bag([("robot1", seq)], tmp_path / "bag", storage=storage, progress=False)
    for side, cal in (("left", seq.rig.left), ("right", seq.rig.right)):
        infos = list(read_bag(bag, [f"/robot1/stereo/{side}/camera_info"]))
        back = camera_info_to_calibration(deserialize_rclpy(infos[-1].data, infos[-1].msgtype))
        for name in ("width", "height", "distortion_model"):
            assert getattr(back, name) == getattr(cal, name)
        for name in ("K", "D", "R", "P"):
            np.testing.assert_array_equal(getattr(back, name), getattr(cal, name))
    assert seq.rig.right.P[0, 3] == -10.0


def test_split_robots_interleaved(tmp_path, kitti_tiny):
    parts = open_sequence("kitti", kitti_tiny).split(2)
    bag = write_dataset_bag([("robot1", parts[0]), ("robot2", parts[1])], tmp_path / "bag", progress=False)
    info = bag_info(bag)
    assert info.topics["/robot1/stereo/left/image_raw"].count == 2
    assert info.topics["/robot2/stereo/left/image_raw"].count == 2
    assert info.topics["/clock"].count == 2 and info.topics["/tf_static"].count == 2
    order = [(m.stamp_ns, m.topic) for m in read_bag(bag) if m.topic.endswith("left/image_raw")]
    assert order == [(0, "/robot1/stereo/left/image_raw"), (0, "/robot2/stereo/left/image_raw"),
                     (100_000_000, "/robot1/stereo/left/image_raw"), (100_000_000, "/robot2/stereo/left/image_raw")]
    # robot2 starts at its own ground-truth pose, 2 m ahead in the whole sequence's map frame
    series = read_series(bag, ["robot1", "robot2"], ["ground_truth"])
    np.testing.assert_allclose(series["robot2"]["ground_truth"].arrays()[1], [[2, 0, 0], [3, 0, 0]], atol=1e-12)
    np.testing.assert_allclose(series["robot1"]["ground_truth"].arrays()[1], [[0, 0, 0], [1, 0, 0]], atol=1e-12)


def test_bag_errors(tmp_path, kitti_tiny):
    seq = open_sequence("kitti", kitti_tiny)
    (tmp_path / "exists").mkdir()
    with pytest.raises(BagError, match="exists"):
        write_dataset_bag([("robot1", seq)], tmp_path / "exists", progress=False)
    with pytest.raises(BagError, match="unique"):
        write_dataset_bag([("robot1", seq), ("robot1", seq)], tmp_path / "dup", progress=False)


def test_import_command(tmp_path, kitti_tiny, capsys):
    out = tmp_path / "bag"
    assert import_main(["kitti", str(kitti_tiny), "--out", str(out), "--split", "2", "--storage", "sqlite3",
                        "--robots-prefix", "car", "--quiet"]) == 0
    assert f"wrote {out} (sqlite3): 4 stereo pairs of 07 (kitti, with ground truth) as car1 (2), car2 (2)" \
        in capsys.readouterr().out
    assert {"/car1/ground_truth", "/car2/stereo/right/image_raw"} <= set(bag_info(out).topics)
    (kitti_tiny / "image_0" / "000001.png").write_bytes(b"broken")
    for argv, problem in [
        (["kitti", str(kitti_tiny), "--out", str(out)], f"--out {out} exists already"),
        (["kitti", str(tmp_path / "none"), "--out", str(tmp_path / "b")], "no such folder"),
        (["tum", str(kitti_tiny), "--out", str(tmp_path / "b")], "unknown dataset format 'tum'"),
        (["euroc", str(kitti_tiny), "--out", str(tmp_path / "b")], "is not a EuRoC/ASL sequence folder"),
        (["kitti", str(kitti_tiny), "--out", str(tmp_path / "b"), "--split", "5"], "--split 5: need 1 <= K <= 4"),
        (["kitti", str(kitti_tiny), "--out", str(tmp_path / "b"), "--split", "0"], "--split 0: need 1 <= K <= 4"),
        (["kitti", str(kitti_tiny)], "the following arguments are required: --out"),
        (["kitti", str(kitti_tiny), "--out", str(tmp_path / "b"), "--quiet"], "000001.png: missing, or not a readable"),
    ]:
        assert import_main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("mrslam dataset import: ") and problem in err and err.count("\n") == 1, err
    assert not (tmp_path / "b").exists()  # the unfinished bag was removed


def test_real_euroc_calibration_and_right_camera(tmp_path, shared_data):
    """The micro sample's raw (distorted) calibration round-trips, and the right camera's tf equals T_BS."""
    folder = shared_data / "euroc_v101_micro"
    if not (folder / "cam0" / "sensor.yaml").is_file():
        pytest.skip(f"EuRoC micro sample not found at {folder}")
    seq = open_sequence("euroc", folder)
    seq = dataclasses.replace(seq, frames=seq.frames[:2])
    bag = write_dataset_bag([("robot1", seq)], tmp_path / "bag", storage="mcap", progress=False)
    info = list(read_bag(bag, ["/robot1/stereo/right/camera_info"]))[0]
    back = camera_info_to_calibration(deserialize_rclpy(info.data, info.msgtype))
    assert back.distortion_model == "radial-tangential"
    for name in ("K", "D", "R", "P"):
        np.testing.assert_array_equal(getattr(back, name), getattr(seq.rig.right, name))
    tf = deserialize(*next((m.data, m.msgtype) for m in read_bag(bag, ["/tf_static"]))).transforms

    def t_bs(cam: str) -> np.ndarray:
        text = (folder / cam / "sensor.yaml").read_text().split("\n", 1)[1]  # past "%YAML:1.0"
        return np.array(yaml.safe_load(text)["T_BS"]["data"], float).reshape(4, 4)

    # base_link <- right = base_link <- left · (T_BS0⁻¹ · T_BS1)
    np.testing.assert_allclose(_tf_matrix(tf[1]), T_BASE_CAM @ np.linalg.inv(t_bs("cam0")) @ t_bs("cam1"), atol=1e-9)
