"""ROS messages <-> the arrays and value objects of mrslam_core (the only place that knows both).

Frames and units follow REP-103/105: metres, radians, stamps as integer nanoseconds in the core.
Every decoder checks the layout it is given and raises :class:`ConversionError` with the reason,
so a node can count and drop a bad message instead of crashing.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import (
    Point,
    Pose,
    PoseArray,
    PoseStamped,
    PoseWithCovarianceStamped,
    TransformStamped,
)
from nav_msgs.msg import OccupancyGrid, Odometry, Path
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image, LaserScan, PointCloud2, PointField
from visualization_msgs.msg import Marker, MarkerArray

from mrslam_core.frontend.camera import CameraCalibration
from mrslam_core.frontend.frontend import ENCODINGS as FRONTEND_ENCODINGS
from mrslam_core.geometry.se2 import quaternion_to_yaw, yaw_to_quaternion
from mrslam_core.types import ObservationSet, RobotSighting


class ConversionError(ValueError):
    """A message whose content or layout cannot be converted."""


# ----------------------------------------------------------------------------- time
def stamp_to_ns(stamp: Time) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def ns_to_stamp(ns: int) -> Time:
    """Time [ns] -> builtin_interfaces/Time; ConversionError beyond its int32 seconds."""
    sec = int(ns) // 1_000_000_000
    if not -(2**31) <= sec < 2**31:
        raise ConversionError(f"stamp {ns} ns does not fit builtin_interfaces/Time")
    return Time(sec=sec, nanosec=int(ns) % 1_000_000_000)


# ----------------------------------------------------------------------------- images
#: the image encodings the frontend takes, as (dtype, channels)
_ENCODINGS = {name: (dtype, channels) for name, (channels, dtype, _) in FRONTEND_ENCODINGS.items()}


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
    if not ((arr.ndim == 2 and channels == 1) or (arr.ndim == 3 and arr.shape[2] == channels)):
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
    if obs.z.shape[1] != 3:
        raise ConversionError(f"observation clouds carry 3D points, got dimension {obs.z.shape[1]}")
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


def _cloud_columns(msg: PointCloud2) -> tuple[Callable[..., np.ndarray], set[str]]:
    """The points of a little-endian PointCloud2 as a reader of its fields: ``column(name, dtype,
    count)`` -> (N, count) of that field (``dtype`` float or int; ``count`` 0: any), and the field
    names. Raises ConversionError on big-endian data, a point step or row step that does not
    hold the points, a buffer shorter than the header promises, or a field of another type or
    count, or outside the point step."""
    by_name = {f.name: f for f in msg.fields}
    if msg.is_bigendian:
        raise ConversionError("big-endian clouds are not supported")
    n = int(msg.width) * int(msg.height)
    step = int(msg.point_step)
    if n and step <= 0:
        raise ConversionError(f"cloud of {n} points has point_step {step}")
    row = int(msg.width) * step
    row_step = int(msg.row_step) if msg.row_step else row
    if row_step < row:
        raise ConversionError(f"row_step {row_step} is shorter than width × point_step = {row}")
    raw = bytes(msg.data)
    need = row_step * (int(msg.height) - 1) + row if n else 0
    if len(raw) < need:
        raise ConversionError(f"cloud data has {len(raw)} bytes, {n} points of {step} need {need}")
    if n == 0:
        buf = np.zeros((0, max(step, 0)), np.uint8)
    else:
        rows = np.frombuffer(raw[: row_step * int(msg.height)].ljust(row_step * int(msg.height), b"\0"), np.uint8)
        buf = rows.reshape(int(msg.height), row_step)[:, :row].reshape(n, step)

    def column(name: str, dtype, count: int = 1) -> np.ndarray:
        f = by_name[name]
        want = {PointField.FLOAT32: np.float32, PointField.FLOAT64: np.float64, PointField.INT32: np.int32,
                PointField.UINT32: np.uint32}.get(f.datatype)
        if want is None or (dtype is float and want not in (np.float32, np.float64)) or (dtype is int and want not in (np.int32, np.uint32)):
            raise ConversionError(f"field {name} has datatype {f.datatype}")
        size = np.dtype(want).itemsize * f.count
        if f.count < 1 or f.offset + size > step or (count and f.count != count):
            raise ConversionError(f"field {name} (offset {f.offset}, count {f.count}) does not fit the point step {step}")
        return buf[:, f.offset:f.offset + size].copy().view(want).reshape(n, f.count)

    return column, set(by_name)


def cloud_to_observations(msg: PointCloud2, robot: str) -> ObservationSet:
    """PointCloud2 written by :func:`observations_to_cloud` (or any cloud with those fields, in
    any order) -> ObservationSet. Raises ConversionError on missing fields, wrong types or counts,
    big-endian data, or a buffer shorter than the header promises."""
    needed = ("x", "y", "z") + _COV
    column, names = _cloud_columns(msg)
    missing = [n for n in needed + ("track_id",) if n not in names]
    if missing:
        raise ConversionError(f"observation cloud lacks fields {missing}")
    z = np.hstack([column(c, float) for c in ("x", "y", "z")]).astype(float)
    n = len(z)
    tri = np.hstack([column(c, float) for c in _COV]).astype(float)
    cov = np.zeros((n, 3, 3))
    cov[:, _IU[0], _IU[1]] = tri
    cov[:, _IU[1], _IU[0]] = tri
    tracks = column("track_id", int)[:, 0].astype(np.int64)
    desc = column("descriptor", float, 0).astype(np.float32) if "descriptor" in names else np.zeros((n, 0), np.float32)
    if not (np.isfinite(z).all() and np.isfinite(tri).all()):
        raise ConversionError("observation cloud has non-finite points or covariances")
    try:
        return ObservationSet(robot, stamp_to_ns(msg.header.stamp), z, cov, desc, tracks)
    except ValueError as exc:
        raise ConversionError(str(exc)) from exc


# ----------------------------------------------------------------------------- bumper contacts
def contacts_to_cloud(points: np.ndarray, stamp_ns: int, frame_id: str) -> PointCloud2:
    """Bumper contacts (K, 2) (x, y) in base_link [m] -> PointCloud2 with float32 fields x y z
    (z = 0), as a bumper node reports them for costmaps."""
    pts = np.zeros((len(points), 3), np.float32)
    pts[:, :2] = np.asarray(points, float).reshape(-1, 2)
    fields = [PointField(name=c, offset=4 * i, datatype=PointField.FLOAT32, count=1) for i, c in enumerate("xyz")]
    msg = PointCloud2(height=1, width=len(pts), fields=fields, is_bigendian=False, point_step=12,
                      row_step=12 * len(pts), is_dense=True)
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = frame_id
    msg.data = pts.tobytes()
    return msg


def cloud_to_contacts(msg: PointCloud2) -> np.ndarray:
    """A bumper's PointCloud2 (fields x and y at least, in the robot's base_link) -> (K, 2) [m].
    Raises ConversionError on missing fields, non-finite points, or a malformed cloud."""
    column, names = _cloud_columns(msg)
    if not {"x", "y"} <= names:
        raise ConversionError(f"contact cloud lacks fields {sorted({'x', 'y'} - names)}")
    xy = np.hstack([column(c, float) for c in ("x", "y")]).astype(float)
    if not np.isfinite(xy).all():
        raise ConversionError("contact cloud has non-finite points")
    return xy


# ----------------------------------------------------------------------------- robot sightings
#: variance given to what a sighting does not measure (the other robot's height, roll, pitch and
#: heading) in its nav_msgs/Odometry [m², rad²]
UNMEASURED_VARIANCE = 1e6


def sighting_to_msg(s: RobotSighting, stamp_ns: int) -> Odometry:
    """A sighting (range [m], bearing [rad] in the observer's base_link) -> nav_msgs/Odometry:
    the position of ``<target>/base_link`` in ``<observer>/base_link`` (x = r cos b, y = r sin b)
    with its (x, y) covariance J Σ Jᵀ; the other four pose axes unmeasured (a variance of
    :data:`UNMEASURED_VARIANCE`), the twist empty."""
    r, b = (float(v) for v in s.z)
    jac = np.array([[np.cos(b), -r * np.sin(b)], [np.sin(b), r * np.cos(b)]])
    full = np.diag([0.0, 0.0] + [UNMEASURED_VARIANCE] * 4)
    full[:2, :2] = jac @ np.asarray(s.cov, float) @ jac.T
    msg = Odometry()
    msg.header.stamp = ns_to_stamp(int(stamp_ns))
    msg.header.frame_id, msg.child_frame_id = f"{s.observer}/base_link", f"{s.target}/base_link"
    msg.pose.pose = pose_to_msg(np.array([r * np.cos(b), r * np.sin(b), 0.0]))
    msg.pose.covariance = full.ravel().tolist()
    return msg


def msg_to_sighting(msg: Odometry, robot: str) -> tuple[int, RobotSighting]:
    """nav_msgs/Odometry written by :func:`sighting_to_msg` -> (stamp [ns], sighting by
    ``robot``). Raises ConversionError unless its frame is ``<robot>/base_link``, its child
    frame ``<target>/base_link`` of another robot, and its position and (x, y) covariance are
    finite, the covariance positive definite, the position off the observer's origin."""
    observer, target = msg.header.frame_id.split("/")[0], msg.child_frame_id.split("/")[0]
    if msg.header.frame_id != f"{robot}/base_link" or msg.child_frame_id != f"{target}/base_link" or target in ("", robot):
        raise ConversionError(f"a sighting by {robot} must be from {robot}/base_link to another robot's base_link, "
                              f"got {msg.header.frame_id!r} -> {msg.child_frame_id!r}")
    x, y = msg.pose.pose.position.x, msg.pose.pose.position.y
    c = np.asarray(msg.pose.covariance, float)
    if c.size != 36:
        raise ConversionError(f"sighting covariance has {c.size} values, expected 36")
    cxy = c.reshape(6, 6)[:2, :2]
    r = float(np.hypot(x, y))
    if not (np.isfinite([x, y]).all() and np.isfinite(cxy).all()) or r <= 0 or np.linalg.eigvalsh(cxy).min() <= 0:
        raise ConversionError(f"sighting of {target} by {observer}: position {x, y} or covariance not usable")
    jac = np.array([[x / r, y / r], [-y / r**2, x / r**2]])
    return stamp_to_ns(msg.header.stamp), RobotSighting(robot, target, np.array([r, np.arctan2(y, x)]), jac @ cxy @ jac.T)


# ----------------------------------------------------------------------------- poses
def pose_to_msg(pose: np.ndarray) -> Pose:
    """Planar pose (x [m], y [m], θ [rad]) (3,) -> geometry_msgs/Pose."""
    pose = np.asarray(pose, dtype=float)
    if pose.shape != (3,):
        raise ConversionError(f"a planar pose must be (3,), got shape {pose.shape}")
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
    msg.pose.covariance = _planar_cov6(cov)
    return msg


def path_msg(poses: np.ndarray, stamps_ns: np.ndarray, frame_id: str) -> Path:
    """(N, 3) planar poses with stamps (N,) -> nav_msgs/Path."""
    poses, stamps_ns = np.asarray(poses, float), np.asarray(stamps_ns)
    if poses.size == 0 and stamps_ns.size == 0:  # an empty path (e.g. np.array([]))
        poses, stamps_ns = poses.reshape(0, 3), stamps_ns.reshape(0)
    if poses.ndim != 2 or poses.shape[1] != 3 or stamps_ns.shape != (poses.shape[0],):
        raise ConversionError(
            f"path needs poses (N, 3) and stamps (N,), got {poses.shape} and {stamps_ns.shape}"
        )
    msg = Path()
    msg.header.frame_id = frame_id
    if len(stamps_ns):
        msg.header.stamp = ns_to_stamp(int(stamps_ns[-1]))
    msg.poses = [pose_stamped_msg(p, int(t), frame_id) for p, t in zip(poses, stamps_ns)]
    return msg


def start_frame(robot: str) -> str:
    """The frame of a robot's own start pose: its poses before it joins the map are in it."""
    return f"{robot}/start"


def pose_stamped_msg(pose: np.ndarray, stamp_ns: int, frame_id: str) -> PoseStamped:
    """Planar pose (x [m], y [m], θ [rad]) (3,) at ``stamp_ns`` in ``frame_id`` -> PoseStamped."""
    msg = PoseStamped()
    msg.header.frame_id = frame_id
    msg.header.stamp = ns_to_stamp(int(stamp_ns))
    msg.pose = pose_to_msg(pose)
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



def matrix_transform_msg(t: np.ndarray, stamp_ns: int, parent: str, child: str) -> TransformStamped:
    """(4, 4) pose of ``child`` in ``parent`` (p_parent = T · p_child) -> TransformStamped (a
    camera's mount on /tf_static)."""
    from scipy.spatial.transform import Rotation

    t = np.asarray(t, float)
    if t.shape != (4, 4) or not np.isfinite(t).all():
        raise ConversionError(f"transform must be a finite (4, 4) matrix, got shape {t.shape}")
    msg = TransformStamped()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id, msg.child_frame_id = parent, child
    tr = msg.transform.translation
    tr.x, tr.y, tr.z = (float(v) for v in t[:3, 3])
    q = msg.transform.rotation
    q.x, q.y, q.z, q.w = (float(v) for v in Rotation.from_matrix(t[:3, :3]).as_quat())
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

    if not np.isfinite([msg.angle_min, msg.angle_increment, msg.range_max]).all():
        raise ConversionError("laser scan angle_min, angle_increment and range_max must be finite")
    ranges = np.asarray(msg.ranges, float)
    n = ranges.size
    bearings = msg.angle_min + (np.arange(n) + 0.5) * msg.angle_increment
    hit = np.isfinite(ranges) & (ranges >= msg.range_min) & (ranges <= msg.range_max)
    free = np.asarray(msg.intensities, float) if len(msg.intensities) == n else np.full(n, msg.range_max)
    out = np.where(hit, ranges, np.minimum(free, msg.range_max))
    keep = hit | (out > 0)
    return Scan(bearings[keep], out[keep], hit[keep])


# ----------------------------------------------------------------------------- more time, poses, tf
def clock_msg(stamp_ns: int) -> Clock:
    """Sim time [ns] -> rosgraph_msgs/Clock (for /clock)."""
    return Clock(clock=ns_to_stamp(int(stamp_ns)))


def _planar_cov6(cov: np.ndarray) -> list[float]:
    cov = np.asarray(cov, float)
    if cov.shape != (3, 3):
        raise ConversionError(f"planar covariance must be (3, 3), got {cov.shape}")
    full = np.zeros((6, 6))
    full[np.ix_([0, 1, 5], [0, 1, 5])] = cov
    return full.ravel().tolist()


def _cov6_to_planar(values, what: str) -> np.ndarray:
    c = np.asarray(values, float)
    if c.size != 36:
        raise ConversionError(f"{what} covariance has {c.size} values, expected 36")
    c = c.reshape(6, 6)[np.ix_([0, 1, 5], [0, 1, 5])]
    if not np.isfinite(c).all():
        raise ConversionError(f"{what} covariance is not finite")
    return c


def pose_to_odometry(pose: np.ndarray, cov: np.ndarray, stamp_ns: int, frame_id: str, child_frame_id: str,
                     twist: tuple[float, float] | None = None) -> Odometry:
    """Planar pose (x [m], y [m], θ [rad]) of ``child_frame_id`` in ``frame_id`` with its (3, 3)
    covariance (and optionally the body twist (v [m/s], ω [rad/s])) -> nav_msgs/Odometry."""
    msg = Odometry()
    msg.header.stamp = ns_to_stamp(int(stamp_ns))
    msg.header.frame_id, msg.child_frame_id = frame_id, child_frame_id
    msg.pose.pose = pose_to_msg(np.asarray(pose, float))
    msg.pose.covariance = _planar_cov6(cov)
    if twist is not None:
        msg.twist.twist.linear.x, msg.twist.twist.angular.z = float(twist[0]), float(twist[1])
    return msg


def visual_odometry_msg(vo, pose_cov: np.ndarray, dt: float, frame_id: str, child_frame_id: str) -> Odometry:
    """The frontend's visual odometry after a frame -> nav_msgs/Odometry.

    Args:
        vo: :class:`mrslam_core.frontend.frontend.VisualOdometry` (pose, delta, 6 × 6 covariance of
            the delta over (δθ, δt)).
        pose_cov: (3, 3) covariance of the planar pose (x, y, yaw), accumulated by the caller.
        dt: time since the previous frame [s] (the twist is the delta over it).
        frame_id, child_frame_id: the odometry frame and base_link.

    Returns:
        The full 3D pose with the planar covariance in its x, y, yaw entries, and the body twist
        (delta / dt, the rotation as a rotation vector) with its 6 × 6 covariance in ROS's order
        (vx, vy, vz, ωx, ωy, ωz) [m/s, rad/s].
    """
    from scipy.spatial.transform import Rotation

    msg = Odometry()
    msg.header.stamp = ns_to_stamp(int(vo.stamp_ns))
    msg.header.frame_id, msg.child_frame_id = frame_id, child_frame_id
    pose = np.asarray(vo.pose, float)
    p, o = msg.pose.pose.position, msg.pose.pose.orientation
    p.x, p.y, p.z = (float(v) for v in pose[:3, 3])
    o.x, o.y, o.z, o.w = (float(v) for v in Rotation.from_matrix(pose[:3, :3]).as_quat())
    msg.pose.covariance = _planar_cov6(pose_cov)
    if dt > 0:
        delta = np.asarray(vo.delta, float)
        rv = Rotation.from_matrix(delta[:3, :3]).as_rotvec()
        lin, ang = msg.twist.twist.linear, msg.twist.twist.angular
        lin.x, lin.y, lin.z = (float(v) / dt for v in delta[:3, 3])
        ang.x, ang.y, ang.z = (float(v) / dt for v in rv)
        order = [3, 4, 5, 0, 1, 2]  # (δθ, δt) -> ROS (linear, angular)
        msg.twist.covariance = (np.asarray(vo.cov, float)[np.ix_(order, order)] / dt**2).ravel().tolist()
    return msg


def odometry_twist_covariance(msg: Odometry) -> np.ndarray:
    """(3, 3) covariance of the planar body twist (vx, vy, ωz) of a nav_msgs/Odometry."""
    return _cov6_to_planar(msg.twist.covariance, "twist")


def pose_with_covariance_to_pose(msg: PoseWithCovarianceStamped) -> tuple[int, np.ndarray, np.ndarray]:
    """PoseWithCovarianceStamped -> (stamp [ns], planar pose (3,), covariance (3, 3) of x, y, yaw)."""
    pose = msg_to_pose(msg.pose.pose)
    if not np.isfinite(pose).all():
        raise ConversionError("pose is not finite")
    return stamp_to_ns(msg.header.stamp), pose, _cov6_to_planar(msg.pose.covariance, "pose")


def path_to_poses(msg: Path) -> tuple[np.ndarray, np.ndarray]:
    """nav_msgs/Path -> (planar poses (N, 3), stamps (N,) int64 [ns])."""
    poses = np.array([msg_to_pose(p.pose) for p in msg.poses]).reshape(-1, 3)
    stamps = np.array([stamp_to_ns(p.header.stamp) for p in msg.poses], np.int64)
    return poses, stamps


def pose_array_msg(poses: np.ndarray, stamp_ns: int, frame_id: str) -> PoseArray:
    """(M, 3) planar poses (e.g. one robot's particles) -> geometry_msgs/PoseArray."""
    poses = np.asarray(poses, float)
    if poses.ndim != 2 or poses.shape[1] != 3:
        raise ConversionError(f"poses must be (M, 3), got {poses.shape}")
    msg = PoseArray()
    msg.header.stamp = ns_to_stamp(int(stamp_ns))
    msg.header.frame_id = frame_id
    msg.poses = [pose_to_msg(p) for p in poses]
    return msg


def pose_array_to_poses(msg: PoseArray) -> np.ndarray:
    """geometry_msgs/PoseArray -> (M, 3) planar poses."""
    return np.array([msg_to_pose(p) for p in msg.poses]).reshape(-1, 3)


def transform_to_pose(msg: TransformStamped) -> tuple[int, str, str, np.ndarray]:
    """TransformStamped -> (stamp [ns], parent frame, child frame, planar pose of child in parent)."""
    t, q = msg.transform.translation, msg.transform.rotation
    pose = np.array([t.x, t.y, float(quaternion_to_yaw(np.array([q.x, q.y, q.z, q.w])))])
    if not np.isfinite(pose).all():
        raise ConversionError(f"transform {msg.header.frame_id} -> {msg.child_frame_id} is not finite")
    return stamp_to_ns(msg.header.stamp), msg.header.frame_id, msg.child_frame_id, pose



def transform_to_arrays(msg: TransformStamped) -> tuple[int, str, str, np.ndarray, np.ndarray]:
    """TransformStamped -> (stamp [ns], parent frame, child frame, translation (3,) [m], rotation
    quaternion (4,) (x, y, z, w)), in 3-D (a camera's mount as well as a planar pose)."""
    t, q = msg.transform.translation, msg.transform.rotation
    xyz, quat = np.array([t.x, t.y, t.z], float), np.array([q.x, q.y, q.z, q.w], float)
    if not (np.isfinite(xyz).all() and np.isfinite(quat).all()):
        raise ConversionError(f"transform {msg.header.frame_id} -> {msg.child_frame_id} is not finite")
    return stamp_to_ns(msg.header.stamp), msg.header.frame_id, msg.child_frame_id, xyz, quat

def tf_message(transforms: Sequence[TransformStamped]):
    """TransformStamped list -> tf2_msgs/TFMessage (for /tf and /tf_static).

    Raises:
        ConversionError: tf2_msgs was not generated (scripts/build_interfaces.sh).
    """
    try:
        from tf2_msgs.msg import TFMessage
    except ImportError as exc:
        raise ConversionError(f"tf2_msgs is not importable ({exc}); run scripts/build_interfaces.sh") from exc
    return TFMessage(transforms=list(transforms))


# ----------------------------------------------------------------------------- grids
def log_odds_to_occupancy(log_odds: np.ndarray, origin: np.ndarray, resolution: float, stamp_ns: int,
                          frame_id: str = "map", unknown_abs: float = 1e-6) -> OccupancyGrid:
    """(H, W) log-odds grid -> OccupancyGrid; cells with |log-odds| <= ``unknown_abs`` (never
    updated) are unknown (−1). ``origin`` = (x, y[, θ]) of cell (0, 0)'s corner in ``frame_id`` [m]."""
    lo = np.asarray(log_odds, float)
    if lo.ndim != 2:
        raise ConversionError(f"grid must be (H, W), got {lo.shape}")
    prob = 1.0 / (1.0 + np.exp(-np.clip(lo, -50, 50)))
    return occupancy_msg(prob, np.abs(lo) > unknown_abs, np.asarray(origin, float), resolution, stamp_ns, frame_id)


def occupancy_to_arrays(msg: OccupancyGrid) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """OccupancyGrid -> (probability (H, W) in [0, 1] (0.5 where unknown), known mask (H, W),
    origin (x, y, θ) [m, rad], resolution [m/cell]). Row i is y = origin_y + (i + ½)·resolution."""
    h, w = int(msg.info.height), int(msg.info.width)
    data = np.asarray(msg.data, np.int8)
    if data.size != h * w:
        raise ConversionError(f"grid has {data.size} cells, header says {h}×{w}")
    if not msg.info.resolution > 0:
        raise ConversionError(f"grid resolution {msg.info.resolution} is not positive")
    grid = data.reshape(h, w).astype(float)
    known = grid >= 0
    if (grid > 100).any():
        raise ConversionError("grid values above 100")
    o = msg.info.origin
    yaw = float(quaternion_to_yaw(np.array([o.orientation.x, o.orientation.y, o.orientation.z, o.orientation.w])))
    return np.where(known, grid / 100.0, 0.5), known, np.array([o.position.x, o.position.y, yaw]), float(msg.info.resolution)


# ----------------------------------------------------------------------------- markers
def landmark_markers(mean: np.ndarray, cov: np.ndarray, stamp_ns: int, frame_id: str = "map",
                     ns: str = "landmarks", n_sigma: float = 2.0, rgba=(0.1, 0.6, 1.0, 0.6),
                     min_size: float = 0.01) -> MarkerArray:
    """Landmark means (N, 3) [m] and covariances (N, 3, 3) [m²] -> MarkerArray of ellipsoids.

    The first marker is a DELETEALL (so landmarks removed from the map vanish); marker ``i + 1`` has
    id ``i``, is centred on ``mean[i]``, oriented along the covariance's eigenvectors and has
    diameters 2·n_sigma·√eigenvalue (at least ``min_size``).
    """
    from scipy.spatial.transform import Rotation

    mean, cov = np.asarray(mean, float), np.asarray(cov, float)
    if mean.size % 3:
        raise ConversionError(f"landmark means must be (N, 3), got shape {mean.shape}")
    mean = mean.reshape(-1, 3)
    if cov.shape != (len(mean), 3, 3):
        raise ConversionError(f"cov must be ({len(mean)}, 3, 3), got {cov.shape}")
    if not (np.isfinite(mean).all() and np.isfinite(cov).all()):
        raise ConversionError("landmarks are not finite")
    out = MarkerArray()
    clear = Marker(ns=ns, action=Marker.DELETEALL)
    clear.header.frame_id = frame_id
    out.markers.append(clear)
    if not len(mean):
        return out
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.transpose(0, 2, 1)))
    vecs[np.linalg.det(vecs) < 0, :, 2] *= -1  # proper rotations
    quats = Rotation.from_matrix(vecs).as_quat()  # x, y, z, w
    sizes = np.maximum(2.0 * n_sigma * np.sqrt(np.clip(vals, 0.0, None)), min_size)
    stamp = ns_to_stamp(int(stamp_ns))
    for i in range(len(mean)):
        m = Marker(ns=ns, id=i, type=Marker.SPHERE, action=Marker.ADD)
        m.header.stamp, m.header.frame_id = stamp, frame_id
        m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in mean[i])
        m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w = (float(v) for v in quats[i])
        m.scale.x, m.scale.y, m.scale.z = (float(v) for v in sizes[i])
        m.color.r, m.color.g, m.color.b, m.color.a = (float(v) for v in rgba)
        out.markers.append(m)
    return out




def marker_ellipsoids(msg: MarkerArray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The SPHERE markers of a MarkerArray (as :func:`landmark_markers` writes them) -> centres
    (N, 3) [m], orientations (N, 4) (x, y, z, w) and diameters (N, 3) [m]."""
    spheres = [m for m in msg.markers if m.type == Marker.SPHERE and m.action == Marker.ADD]
    centres = np.array([(m.pose.position.x, m.pose.position.y, m.pose.position.z) for m in spheres], float)
    quats = np.array([(m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w)
                      for m in spheres], float)
    sizes = np.array([(m.scale.x, m.scale.y, m.scale.z) for m in spheres], float)
    return centres.reshape(-1, 3), quats.reshape(-1, 4), sizes.reshape(-1, 3)

def points_marker(xy: np.ndarray, stamp_ns: int, frame_id: str, ns: str, size: float = 0.25,
                  rgba=(1.0, 0.5, 0.0, 0.9)) -> MarkerArray:
    """Points (N, 2) or (N, 3) [m] -> a MarkerArray of one SPHERE_LIST (id 0, namespace ``ns``),
    spheres ``size`` [m] across; an empty list clears the points a viewer shows."""
    pts = np.asarray(xy, float)
    if pts.size == 0:
        pts = pts.reshape(0, 2)
    if pts.ndim != 2 or pts.shape[1] not in (2, 3) or not np.isfinite(pts).all():
        raise ConversionError(f"points must be finite (N, 2) or (N, 3), got shape {pts.shape}")
    m = Marker(ns=ns, id=0, type=Marker.SPHERE_LIST, action=Marker.ADD)
    m.header.stamp, m.header.frame_id = ns_to_stamp(int(stamp_ns)), frame_id
    m.pose.orientation.w = 1.0
    m.scale.x = m.scale.y = m.scale.z = float(size)
    m.color.r, m.color.g, m.color.b, m.color.a = (float(v) for v in rgba)
    for p in pts:
        q = Point(x=float(p[0]), y=float(p[1]), z=float(p[2]) if len(p) == 3 else 0.0)
        m.points.append(q)
    return MarkerArray(markers=[m])


def marker_points(msg: MarkerArray) -> np.ndarray:
    """The points (N, 3) [m] of a MarkerArray's SPHERE_LIST / POINTS markers (frontiers)."""
    pts = [(p.x, p.y, p.z) for m in msg.markers if m.type in (Marker.SPHERE_LIST, Marker.POINTS) for p in m.points]
    return np.array(pts, float).reshape(-1, 3)

# ----------------------------------------------------------------------------- diagnostics
LEVELS = {"ok": DiagnosticStatus.OK, "warn": DiagnosticStatus.WARN, "error": DiagnosticStatus.ERROR,
          "stale": DiagnosticStatus.STALE}


def diagnostics_msg(name: str, counters: Mapping[str, float], stamp_ns: int, level: str = "ok",
                    message: str = "", hardware_id: str = "") -> DiagnosticArray:
    """Named counters (drops by reason, latencies, ...) -> diagnostic_msgs/DiagnosticArray with one
    status; keys sorted, values as text (integers without a decimal point)."""
    if level not in LEVELS:
        raise ConversionError(f"diagnostic level {level!r} not in {sorted(LEVELS)}")
    status = DiagnosticStatus(level=LEVELS[level], name=name, message=message, hardware_id=hardware_id)
    status.values = [KeyValue(key=str(k), value=str(int(v)) if float(v).is_integer() else f"{float(v):.6g}")
                     for k, v in sorted(counters.items())]
    msg = DiagnosticArray(status=[status])
    msg.header.stamp = ns_to_stamp(int(stamp_ns))
    return msg


def diagnostics_to_counters(msg: DiagnosticArray) -> dict[str, dict[str, float]]:
    """DiagnosticArray -> {status name: {key: value}} (values that are not numbers are skipped)."""
    out: dict[str, dict[str, float]] = {}
    for st in msg.status:
        values = {}
        for kv in st.values:
            try:
                values[kv.key] = float(kv.value)
            except ValueError:
                continue
        out[st.name] = values
    return out
