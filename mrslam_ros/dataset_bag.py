"""A public stereo dataset sequence (or its segments, one per robot) as a rosbag2 recording.

The bag holds what the simulator publishes, under the same topic and frame names, so that
``mrslam replay BAG`` feeds the frontend nodes unchanged (:mod:`mrslam_ros.sim_node`,
:mod:`mrslam_ros.frontend_node`). Per robot ``<r>``:

==========================================  ============================  ==================================
topic                                       type                          frame (header.frame_id)
==========================================  ============================  ==================================
``/<r>/stereo/left/image_raw``              sensor_msgs/msg/Image mono8   ``<r>/camera_left_optical``
``/<r>/stereo/right/image_raw``             sensor_msgs/msg/Image mono8   ``<r>/camera_right_optical``
``/<r>/stereo/left/camera_info``            sensor_msgs/msg/CameraInfo    ``<r>/camera_left_optical``
``/<r>/stereo/right/camera_info``           sensor_msgs/msg/CameraInfo    ``<r>/camera_right_optical``
``/<r>/ground_truth`` (with ground truth)   nav_msgs/msg/Odometry         ``map``, child ``<r>/base_link``
==========================================  ============================  ==================================

and for all robots ``/tf_static`` (tf2_msgs/msg/TFMessage: one message per robot, before
everything else, with ``<r>/base_link -> <r>/camera_left_optical`` from the rig's ``t_base_cam``
and ``<r>/base_link -> <r>/camera_right_optical`` (the raw right camera, from the rectification))
and ``/clock`` (rosgraph_msgs/msg/Clock, one message at every distinct frame stamp, before that
stamp's frames). Every message is logged at its header stamp; messages of all robots are
interleaved in stamp order (per stamp: clock, then robots in order; per robot: the two camera_info,
the two images, the ground truth). CameraInfo is written with every image pair, as the simulator
does. Ground truth is the full 3D pose with zero covariance and zero twist. The bag carries no
QoS metadata: a player then uses the project's convention (``/tf_static`` latched).

The frontend node takes its extrinsic from the ``t_base_cam`` parameter, not from /tf_static:
give it :data:`mrslam_core.datasets.stereo.T_BASE_CAM` for a dataset bag.

No ROS is needed: the messages are built with the rosbags typestore (ROS 2 Jazzy).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from mrslam_core.datasets.stereo import StereoSequence, rig_t_base_cam
from mrslam_core.frontend.camera import CameraCalibration, StereoRig
from mrslam_ros.bag import BagError, BagWriter, serialize, typestore

IMAGE = "sensor_msgs/msg/Image"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
ODOMETRY = "nav_msgs/msg/Odometry"
CLOCK = "rosgraph_msgs/msg/Clock"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"


def image_topic(robot: str, side: str) -> str:
    """``/<robot>/stereo/<side>/image_raw`` (side ``left`` or ``right``)."""
    return f"/{robot}/stereo/{side}/image_raw"


def camera_info_topic(robot: str, side: str) -> str:
    """``/<robot>/stereo/<side>/camera_info``."""
    return f"/{robot}/stereo/{side}/camera_info"


def ground_truth_topic(robot: str) -> str:
    """``/<robot>/ground_truth``."""
    return f"/{robot}/ground_truth"


def optical_frame(robot: str, side: str) -> str:
    """``<robot>/camera_<side>_optical``."""
    return f"{robot}/camera_{side}_optical"


def write_dataset_bag(sequences: list[tuple[str, StereoSequence]], out: str | Path, storage: str = "sqlite3",
                      progress: bool = True) -> Path:
    """Write the stereo sequences, one robot each, into a new rosbag2 (see the module docstring).

    Args:
        sequences: (robot name, sequence) pairs; names must be unique.
        out: the bag folder to create (must not exist).
        storage: ``"sqlite3"`` or ``"mcap"``.
        progress: show a progress bar on stderr (tqdm when installed).

    Returns:
        ``out``.

    Raises:
        BagError: no sequence, duplicate robot names, ``out`` exists, or an unknown storage.
        mrslam_core.datasets.stereo.DatasetError: an image that cannot be read (the bag written so
            far is closed and kept).
    """
    out = Path(out)
    names = [r for r, _ in sequences]
    if not sequences:
        raise BagError("no sequence to write")
    if len(set(names)) != len(names):
        raise BagError(f"robot names must be unique, got {names}")
    msgs = _Messages()
    # (stamp, robot index, frame index), in stamp order then robot order
    events = sorted((f.stamp_ns, j, i) for j, (_, seq) in enumerate(sequences) for i, f in enumerate(seq.frames))
    total = len(events)
    bar = _Progress(total, f"writing {out.name}") if progress else None
    with BagWriter(out, storage) as writer:
        for robot, seq in sequences:
            for side in ("left", "right"):
                writer.add_topic(image_topic(robot, side), IMAGE)
                writer.add_topic(camera_info_topic(robot, side), CAMERA_INFO)
            if seq.ground_truth is not None:
                writer.add_topic(ground_truth_topic(robot), ODOMETRY)
        writer.add_topic("/tf_static", TF_MESSAGE)
        writer.add_topic("/clock", CLOCK)

        t0 = events[0][0]
        for robot, seq in sequences:
            writer.write("/tf_static", t0, serialize(msgs.tf_static(robot, seq.rig, t0), TF_MESSAGE))
        last_clock = None
        try:
            for done, (stamp, j, i) in enumerate(events, start=1):
                robot, seq = sequences[j]
                if stamp != last_clock:
                    writer.write("/clock", stamp, serialize(msgs.clock(stamp), CLOCK))
                    last_clock = stamp
                left, right = seq.read(i)
                for side, cal in (("left", seq.rig.left), ("right", seq.rig.right)):
                    writer.write(camera_info_topic(robot, side), stamp,
                                 serialize(msgs.camera_info(cal, stamp, optical_frame(robot, side)), CAMERA_INFO))
                for side, image in (("left", left), ("right", right)):
                    writer.write(image_topic(robot, side), stamp,
                                 serialize(msgs.mono8(image, stamp, optical_frame(robot, side)), IMAGE))
                if seq.ground_truth is not None:
                    writer.write(ground_truth_topic(robot), stamp,
                                 serialize(msgs.odometry(seq.ground_truth[i], stamp, robot), ODOMETRY))
                if bar is not None:
                    bar.update(done)
        finally:
            if bar is not None:
                bar.close()
    return out


class _Messages:
    """Builders of the bag's messages from the rosbags typestore classes (no rclpy)."""

    def __init__(self):
        self.t = typestore().types

    def header(self, stamp_ns: int, frame_id: str):
        time_cls = self.t["builtin_interfaces/msg/Time"]
        return self.t["std_msgs/msg/Header"](
            stamp=time_cls(sec=int(stamp_ns) // 1_000_000_000, nanosec=int(stamp_ns) % 1_000_000_000),
            frame_id=frame_id)

    def clock(self, stamp_ns: int):
        return self.t[CLOCK](clock=self.header(stamp_ns, "").stamp)

    def mono8(self, image: np.ndarray, stamp_ns: int, frame_id: str):
        """(H, W) uint8 -> sensor_msgs/Image mono8, rows packed (step = W)."""
        image = np.ascontiguousarray(image, np.uint8)
        h, w = image.shape
        return self.t[IMAGE](header=self.header(stamp_ns, frame_id), height=h, width=w, encoding="mono8",
                             is_bigendian=0, step=w, data=image.reshape(-1))

    def camera_info(self, cal: CameraCalibration, stamp_ns: int, frame_id: str):
        """CameraCalibration -> sensor_msgs/CameraInfo (the inverse of conversions.camera_info_to_calibration)."""
        roi = self.t["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        return self.t[CAMERA_INFO](
            header=self.header(stamp_ns, frame_id), height=int(cal.height), width=int(cal.width),
            distortion_model=cal.distortion_model, d=np.asarray(cal.D, np.float64).ravel().copy(),
            k=np.asarray(cal.K, np.float64).ravel().copy(), r=np.asarray(cal.R, np.float64).ravel().copy(),
            p=np.asarray(cal.P, np.float64).ravel().copy(), binning_x=0, binning_y=0, roi=roi)

    def _pose(self, t: np.ndarray):
        q = Rotation.from_matrix(t[:3, :3]).as_quat()  # x y z w
        point = self.t["geometry_msgs/msg/Point"](x=float(t[0, 3]), y=float(t[1, 3]), z=float(t[2, 3]))
        return self.t["geometry_msgs/msg/Pose"](position=point, orientation=self._quaternion(q))

    def _quaternion(self, q: np.ndarray):
        return self.t["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))

    def _vector(self, v: np.ndarray):
        return self.t["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def odometry(self, t_map_base: np.ndarray, stamp_ns: int, robot: str):
        """(4, 4) map <- base_link -> nav_msgs/Odometry in ``map``, child ``<robot>/base_link``."""
        zero = np.zeros(3)
        twist = self.t["geometry_msgs/msg/Twist"](linear=self._vector(zero), angular=self._vector(zero))
        return self.t[ODOMETRY](
            header=self.header(stamp_ns, "map"), child_frame_id=f"{robot}/base_link",
            pose=self.t["geometry_msgs/msg/PoseWithCovariance"](pose=self._pose(t_map_base), covariance=np.zeros(36)),
            twist=self.t["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)))

    def transform(self, t: np.ndarray, stamp_ns: int, parent: str, child: str):
        tr = self.t["geometry_msgs/msg/Transform"](translation=self._vector(t[:3, 3]),
                                                   rotation=self._quaternion(Rotation.from_matrix(t[:3, :3]).as_quat()))
        return self.t["geometry_msgs/msg/TransformStamped"](header=self.header(stamp_ns, parent), child_frame_id=child,
                                                            transform=tr)

    def tf_static(self, robot: str, rig: StereoRig, stamp_ns: int):
        """base_link -> left and right optical frames of one robot's rig."""
        base = f"{robot}/base_link"
        t_base_left = rig_t_base_cam(rig)
        return self.t[TF_MESSAGE](transforms=[
            self.transform(t_base_left, stamp_ns, base, optical_frame(robot, "left")),
            self.transform(t_base_left @ _t_left_right(rig), stamp_ns, base, optical_frame(robot, "right")),
        ])


def _t_left_right(rig: StereoRig) -> np.ndarray:
    """(4, 4) raw left optical <- raw right optical frame, from the rectification.

    The rectified right frame is the rectified left one moved by the baseline b along x:
    p_left = R_lᵀ · (R_r · p_right + [b, 0, 0]).
    """
    out = np.eye(4)
    out[:3, :3] = rig.left.R.T @ rig.right.R
    out[:3, 3] = rig.left.R.T @ np.array([rig.baseline, 0.0, 0.0])
    return out


class _Progress:
    """A progress bar on stderr: tqdm when installed, else a plain ``[#####   ]  42.0 %`` line."""

    def __init__(self, total: int, label: str):
        self.total, self.label = max(int(total), 1), label
        self.start = time.monotonic()
        try:
            from tqdm import tqdm
        except ImportError:
            self._tqdm = None
        else:
            self._tqdm = tqdm(total=total, desc=label, unit="frame", file=sys.stderr)
        self._shown = 0

    def update(self, done: int) -> None:
        if self._tqdm is not None:
            self._tqdm.update(done - self._shown)
            self._shown = done
            return
        if done != self.total and done - self._shown < max(self.total // 100, 1):
            return
        self._shown = done
        frac = done / self.total
        rate = done / max(time.monotonic() - self.start, 1e-9)
        bar = "#" * int(30 * frac)
        print(f"\r  {self.label} [{bar:<30}] {100 * frac:5.1f} %  {rate:6.1f} frame/s", end="", file=sys.stderr,
              flush=True)

    def close(self) -> None:
        if self._tqdm is not None:
            self._tqdm.close()
        else:
            print(file=sys.stderr)
