"""ROS messages <-> the arrays and value objects of mrslam_core (the only place that knows both).

Frames and units follow REP-103/105: metres, radians, stamps as integer nanoseconds in the core.
Every decoder checks the layout it is given and raises :class:`ConversionError` with the reason,
so a node can count and drop a bad message instead of crashing.
"""

from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Pose, PoseStamped, PoseWithCovarianceStamped, TransformStamped
from nav_msgs.msg import OccupancyGrid, Odometry, Path
from sensor_msgs.msg import CameraInfo, Image, LaserScan, PointCloud2, PointField

from mrslam_core.frontend.camera import CameraCalibration
from mrslam_core.geometry.se2 import quaternion_to_yaw, yaw_to_quaternion
from mrslam_core.types import ObservationSet


class ConversionError(ValueError):
    """A message whose content or layout cannot be converted."""


# ----------------------------------------------------------------------------- time
def stamp_to_ns(stamp: Time) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def ns_to_stamp(ns: int) -> Time:
    return Time(sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000))


# ----------------------------------------------------------------------------- images
_ENCODINGS = {"mono8": (np.uint8, 1), "mono16": (np.uint16, 1), "rgb8": (np.uint8, 3), "bgr8": (np.uint8, 3),
              "rgba8": (np.uint8, 4), "bgra8": (np.uint8, 4)}


def image_to_array(msg: Image) -> np.ndarray:
    """sensor_msgs/Image -> (H, W) or (H, W, C) array (a copy), checked against height, width,
    step and encoding."""
    if msg.encoding not in _ENCODINGS:
        raise ConversionError(f"unsupported image encoding {msg.encoding!r} (have {sorted(_ENCODINGS)})")
    dtype, channels = _ENCODINGS[msg.encoding]
    itemsize = np.dtype(dtype).itemsize
    row = msg.width * channels * itemsize
    if msg.height == 0 or msg.width == 0:
        raise ConversionError("empty image")
    if msg.step < row:
        raise ConversionError(f"step {msg.step} is shorter than a row of {row} bytes")
    data = np.frombuffer(bytes(msg.data), np.uint8)
    if data.size < msg.step * msg.height:
        raise ConversionError(f"image data has {data.size} bytes, expected {msg.step * msg.height}")
    rows = data[: msg.step * msg.height].reshape(msg.height, msg.step)[:, :row]
    arr = rows.copy().view(dtype)
    if itemsize > 1 and bool(msg.is_bigendian) != (np.little_endian is False):
        arr = arr.byteswap()
    return arr.reshape(msg.height, msg.width, channels) if channels > 1 else arr.reshape(msg.height, msg.width)


def array_to_image(arr: np.ndarray, encoding: str, stamp_ns: int, frame_id: str) -> Image:
    """(H, W[, C]) array -> sensor_msgs/Image with the given encoding."""
    if encoding not in _ENCODINGS:
        raise ConversionError(f"unsupported image encoding {encoding!r}")
    dtype, channels = _ENCODINGS[encoding]
    arr = np.ascontiguousarray(arr, dtype=dtype)
    if (arr.ndim == 2 and channels != 1) or (arr.ndim == 3 and arr.shape[2] != channels):
        raise ConversionError(f"array of shape {arr.shape} does not fit encoding {encoding}")
    msg = Image(height=arr.shape[0], width=arr.shape[1], encoding=encoding, is_bigendian=0,
                step=arr.shape[1] * channels * arr.itemsize)
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = frame_id
    msg.data = arr.tobytes()
    return msg


# ----------------------------------------------------------------------------- cameras
def camera_info_to_calibration(msg: CameraInfo) -> CameraCalibration:
    """CameraInfo -> CameraCalibration (K, D, R, P checked by the dataclass)."""
    if msg.width == 0 or msg.height == 0 or msg.k[0] == 0.0:
        raise ConversionError("camera_info is empty (zero size or focal length)")
    try:
        return CameraCalibration(width=msg.width, height=msg.height, K=np.array(msg.k).reshape(3, 3),
                                 D=np.array(msg.d, float), R=np.array(msg.r).reshape(3, 3),
                                 P=np.array(msg.p).reshape(3, 4), distortion_model=msg.distortion_model or "plumb_bob")
    except ValueError as exc:
        raise ConversionError(f"camera_info: {exc}") from exc


def calibration_to_camera_info(cal: CameraCalibration, stamp_ns: int, frame_id: str) -> CameraInfo:
    msg = CameraInfo(width=int(cal.width), height=int(cal.height), distortion_model=cal.distortion_model)
    msg.k = np.asarray(cal.K, float).ravel().tolist()
    msg.d = np.asarray(cal.D, float).ravel().tolist()
    msg.r = np.asarray(cal.R, float).ravel().tolist()
    msg.p = np.asarray(cal.P, float).ravel().tolist()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = frame_id
    return msg


# ----------------------------------------------------------------------------- observations
_COV = ("cxx", "cxy", "cxz", "cyy", "cyz", "czz")
_IU = np.triu_indices(3)


def observations_to_cloud(obs: ObservationSet, frame_id: str) -> PointCloud2:
    """ObservationSet (3D points in base_link) -> PointCloud2 with fields x y z, the six upper
    covariance terms, track_id (int32) and descriptor (float32, count = D), little-endian."""
    b, d = len(obs), obs.descriptors.shape[1]
    fields, offset = [], 0
    for name in ("x", "y", "z") + _COV:
        fields.append(PointField(name=name, offset=offset, datatype=PointField.FLOAT32, count=1))
        offset += 4
    fields.append(PointField(name="track_id", offset=offset, datatype=PointField.INT32, count=1))
    offset += 4
    if d:
        fields.append(PointField(name="descriptor", offset=offset, datatype=PointField.FLOAT32, count=d))
        offset += 4 * d
    rec = np.zeros((b, offset // 4), np.float32)
    rec[:, :3] = obs.z
    rec[:, 3:9] = obs.cov[:, _IU[0], _IU[1]]
    rec[:, 9] = obs.track_ids.astype(np.int32).view(np.float32)
    rec[:, 10:] = obs.descriptors
    msg = PointCloud2(height=1, width=b, fields=fields, is_bigendian=False, point_step=offset,
                      row_step=offset * b, is_dense=True)
    msg.header.stamp = ns_to_stamp(obs.stamp_ns)
    msg.header.frame_id = frame_id
    msg.data = rec.tobytes()
    return msg


def cloud_to_observations(msg: PointCloud2, robot: str) -> ObservationSet:
    """PointCloud2 written by :func:`observations_to_cloud` (or any cloud with those fields, in
    any order) -> ObservationSet. Raises ConversionError on missing fields, wrong types or counts,
    big-endian data, or a buffer shorter than the header promises."""
    by_name = {f.name: f for f in msg.fields}
    needed = ("x", "y", "z") + _COV
    missing = [n for n in needed + ("track_id",) if n not in by_name]
    if missing:
        raise ConversionError(f"observation cloud lacks fields {missing}")
    if msg.is_bigendian:
        raise ConversionError("big-endian clouds are not supported")
    n = int(msg.width) * int(msg.height)
    step = int(msg.point_step)
    raw = bytes(msg.data)
    if len(raw) < n * step:
        raise ConversionError(f"cloud data has {len(raw)} bytes, {n} points of {step} need {n * step}")
    buf = np.frombuffer(raw[: n * step], np.uint8).reshape(n, step)

    def column(name: str, dtype, count: int = 1) -> np.ndarray:
        f = by_name[name]
        want = {PointField.FLOAT32: np.float32, PointField.FLOAT64: np.float64, PointField.INT32: np.int32,
                PointField.UINT32: np.uint32}.get(f.datatype)
        if want is None or (dtype is float and want not in (np.float32, np.float64)) or (dtype is int and want not in (np.int32, np.uint32)):
            raise ConversionError(f"field {name} has datatype {f.datatype}")
        size = np.dtype(want).itemsize * f.count
        if f.offset + size > step or (count and f.count != count):
            raise ConversionError(f"field {name} does not fit the point step")
        return buf[:, f.offset:f.offset + size].copy().view(want).reshape(n, f.count)

    z = np.hstack([column(c, float) for c in ("x", "y", "z")]).astype(float)
    tri = np.hstack([column(c, float) for c in _COV]).astype(float)
    cov = np.zeros((n, 3, 3))
    cov[:, _IU[0], _IU[1]] = tri
    cov[:, _IU[1], _IU[0]] = tri
    tracks = column("track_id", int)[:, 0].astype(np.int64)
    desc = column("descriptor", float, 0).astype(np.float32) if "descriptor" in by_name else np.zeros((n, 0), np.float32)
    try:
        return ObservationSet(robot, stamp_to_ns(msg.header.stamp), z, cov, desc, tracks)
    except ValueError as exc:
        raise ConversionError(str(exc)) from exc


# ----------------------------------------------------------------------------- poses
def pose_to_msg(pose: np.ndarray) -> Pose:
    q = yaw_to_quaternion(float(pose[2]))
    msg = Pose()
    msg.position.x, msg.position.y = float(pose[0]), float(pose[1])
    msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w = (float(v) for v in q)
    return msg


def msg_to_pose(msg: Pose) -> np.ndarray:
    """geometry_msgs/Pose -> planar (x, y, θ)."""
    o = msg.orientation
    return np.array([msg.position.x, msg.position.y, float(quaternion_to_yaw(np.array([o.x, o.y, o.z, o.w])))])


def odometry_to_pose(msg: Odometry) -> tuple[int, np.ndarray, np.ndarray]:
    """nav_msgs/Odometry -> (stamp ns, planar pose (3,), planar covariance (3, 3) of x, y, yaw)."""
    pose = msg_to_pose(msg.pose.pose)
    if not np.isfinite(pose).all():
        raise ConversionError("odometry pose is not finite")
    c = np.array(msg.pose.covariance, float).reshape(6, 6)[np.ix_([0, 1, 5], [0, 1, 5])]
    return stamp_to_ns(msg.header.stamp), pose, c


def pose_with_covariance(pose: np.ndarray, cov: np.ndarray, stamp_ns: int, frame_id: str) -> PoseWithCovarianceStamped:
    """Planar pose and (3, 3) covariance of (x, y, yaw) -> PoseWithCovarianceStamped."""
    msg = PoseWithCovarianceStamped()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = frame_id
    msg.pose.pose = pose_to_msg(pose)
    full = np.zeros((6, 6))
    full[np.ix_([0, 1, 5], [0, 1, 5])] = cov
    msg.pose.covariance = full.ravel().tolist()
    return msg


def path_msg(poses: np.ndarray, stamps_ns: np.ndarray, frame_id: str) -> Path:
    """(N, 3) planar poses with stamps (N,) -> nav_msgs/Path."""
    msg = Path()
    msg.header.frame_id = frame_id
    if len(stamps_ns):
        msg.header.stamp = ns_to_stamp(int(stamps_ns[-1]))
    for p, t in zip(poses, stamps_ns):
        ps = PoseStamped()
        ps.header.frame_id = frame_id
        ps.header.stamp = ns_to_stamp(int(t))
        ps.pose = pose_to_msg(p)
        msg.poses.append(ps)
    return msg


def transform_msg(pose: np.ndarray, stamp_ns: int, parent: str, child: str) -> TransformStamped:
    """Planar pose of ``child`` in ``parent`` -> TransformStamped (for /tf)."""
    msg = TransformStamped()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id, msg.child_frame_id = parent, child
    p = pose_to_msg(pose)
    msg.transform.translation.x, msg.transform.translation.y = p.position.x, p.position.y
    msg.transform.rotation = p.orientation
    return msg


# ----------------------------------------------------------------------------- maps
def occupancy_msg(prob: np.ndarray, known: np.ndarray, origin: np.ndarray, resolution: float,
                  stamp_ns: int, frame_id: str = "map") -> OccupancyGrid:
    """(H, W) occupancy probability and known mask -> OccupancyGrid (0..100, −1 unknown);
    row 0 is the cell row at the origin's y (ROS row-major from the origin)."""
    data = np.where(known, np.clip(np.round(prob * 100), 0, 100), -1).astype(np.int8)
    msg = OccupancyGrid()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = frame_id
    msg.info.resolution = float(resolution)
    msg.info.height, msg.info.width = int(prob.shape[0]), int(prob.shape[1])
    msg.info.origin.position.x, msg.info.origin.position.y = float(origin[0]), float(origin[1])
    msg.info.origin.orientation.w = 1.0
    msg.data = data.ravel().tolist()
    return msg


# ----------------------------------------------------------------------------- scans
def obstacle_scan_to_laser(scan, frame_id: str) -> LaserScan:
    """The frontend's pseudo laser scan (ObstacleScan) -> sensor_msgs/LaserScan.

    Bins with an obstacle carry its range; bins known free up to some distance carry +inf when that
    is the full range and otherwise the known-free range in ``intensities`` (0 where unknown), so
    the free-space information survives the message.
    """
    msg = LaserScan()
    msg.header.stamp = ns_to_stamp(scan.stamp_ns)
    msg.header.frame_id = frame_id
    msg.angle_min = float(scan.angle_min)
    msg.angle_increment = float(scan.angle_increment)
    msg.angle_max = float(scan.angle_min + scan.angle_increment * (scan.ranges.size - 1))
    msg.range_min = 0.0
    msg.range_max = float(scan.range_max)
    msg.ranges = np.where(np.isfinite(scan.ranges), scan.ranges, np.inf).astype(np.float32).tolist()
    msg.intensities = np.asarray(scan.free_ranges, np.float32).tolist()
    return msg


def laser_to_scan(msg: LaserScan):
    """sensor_msgs/LaserScan -> the exploration grid's Scan (bearings, ranges, hit).

    Finite ranges within range_max are hits; other beams count as free up to the known-free range
    in ``intensities`` when present, else up to range_max.
    """
    from mrslam_core.exploration.grid import Scan

    ranges = np.asarray(msg.ranges, float)
    n = ranges.size
    bearings = msg.angle_min + (np.arange(n) + 0.5) * msg.angle_increment
    hit = np.isfinite(ranges) & (ranges >= msg.range_min) & (ranges <= msg.range_max)
    free = np.asarray(msg.intensities, float) if len(msg.intensities) == n else np.full(n, msg.range_max)
    out = np.where(hit, ranges, np.minimum(free, msg.range_max))
    keep = hit | (out > 0)
    return Scan(bearings[keep], out[keep], hit[keep])
