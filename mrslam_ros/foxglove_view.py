"""A Foxglove WebSocket view of a running team: arrays in, Foxglove's standard schemas out.

No rclpy here: :mod:`mrslam_ros.view_node` turns ROS messages into arrays with
:mod:`mrslam_ros.conversions` and hands them to :class:`ViewServer`, which logs them on channels of
the Foxglove SDK (``foxglove-sdk``, protobuf encoded ``foxglove.*`` schemas: what the Foxglove app's
3D, Image and Plot panels read without extensions).

The channels (``<robot>`` is each robot's name; every pose in the map frame):

==============================  ==========================  ==========================================
channel                         schema                      content
==============================  ==========================  ==========================================
/tf                             foxglove.FrameTransforms    the TF tree (map -> robot/odom -> robot/base_link)
/<robot>/pose                   foxglove.PoseInFrame        the central filter's estimate
/<robot>/path                   foxglove.PosesInFrame       its estimated path
/<robot>/ground_truth           foxglove.PoseInFrame        ground truth, where known (simulator, datasets)
/<robot>/ground_truth_path      foxglove.PosesInFrame       the ground-truth path so far
/<robot>/goal                   foxglove.PoseInFrame        its exploration goal
/<robot>/plan                   foxglove.PosesInFrame       the planned path to the goal
/<robot>/image                  foxglove.RawImage           the left camera image
/<robot>/image_points           foxglove.ImageAnnotations   the points it observed in that image
/<robot>/camera_calibration     foxglove.CameraCalibration  the left camera
/slam/landmarks                 foxglove.PointCloud         the best particle's landmark means
/slam/landmark_ellipsoids       foxglove.SceneUpdate        their 2-sigma covariance ellipsoids (on request)
/slam/particles                 foxglove.PosesInFrame       every particle's pose of every robot
/map                            foxglove.Grid               the occupancy grid (int8 -1 unknown, 0-100; RGBA)
/exploration/frontiers          foxglove.SceneUpdate        the frontier targets of the last plan
==============================  ==========================  ==========================================

Nothing is built for a channel no client subscribes to (:meth:`ViewServer.wants`), so the view
costs next to nothing while nobody watches. Bad client messages (the SDK answers each with a
status and logs it) are counted in :attr:`ViewServer.client_errors`; the server goes on.
"""

from __future__ import annotations

import logging
import threading
from collections import Counter
from collections.abc import Iterable

import numpy as np

import foxglove
from foxglove import channels as fc
from foxglove import messages as fm
from foxglove.messages import Timestamp
from foxglove.websocket import ServerListener

#: channel-name pattern -> channel class (``{robot}`` stands for each robot's name)
STREAMS: dict[str, type] = {
    "/tf": fc.FrameTransformsChannel,
    "/{robot}/pose": fc.PoseInFrameChannel,
    "/{robot}/path": fc.PosesInFrameChannel,
    "/{robot}/ground_truth": fc.PoseInFrameChannel,
    "/{robot}/ground_truth_path": fc.PosesInFrameChannel,
    "/{robot}/goal": fc.PoseInFrameChannel,
    "/{robot}/plan": fc.PosesInFrameChannel,
    "/{robot}/image": fc.RawImageChannel,
    "/{robot}/image_points": fc.ImageAnnotationsChannel,
    "/{robot}/camera_calibration": fc.CameraCalibrationChannel,
    "/slam/landmarks": fc.PointCloudChannel,
    "/slam/landmark_ellipsoids": fc.SceneUpdateChannel,
    "/slam/particles": fc.PosesInFrameChannel,
    "/map": fc.GridChannel,
    "/exploration/frontiers": fc.SceneUpdateChannel,
}


def channel_names(robots: Iterable[str], ellipsoids: bool = True) -> dict[str, type]:
    """Every channel of a team ``robots``: name -> channel class."""
    out = {}
    for pattern, cls in STREAMS.items():
        if pattern == "/slam/landmark_ellipsoids" and not ellipsoids:
            continue
        for robot in (robots if "{robot}" in pattern else [""]):
            out[pattern.format(robot=robot)] = cls
    return out


# ----------------------------------------------------------------------------- message builders
def timestamp(stamp_ns: int) -> Timestamp:
    """Integer nanoseconds -> foxglove Timestamp."""
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    return Timestamp(sec, nsec)


def _quaternion(yaw: float) -> fm.Quaternion:
    return fm.Quaternion(x=0.0, y=0.0, z=float(np.sin(yaw / 2)), w=float(np.cos(yaw / 2)))


def planar_pose(pose: np.ndarray, z: float = 0.0) -> fm.Pose:
    """(x, y, θ) [m, rad] -> foxglove Pose at height ``z`` [m]."""
    return fm.Pose(position=fm.Vector3(x=float(pose[0]), y=float(pose[1]), z=float(z)), orientation=_quaternion(float(pose[2])))


def pose_in_frame(pose: np.ndarray, stamp_ns: int, frame_id: str) -> fm.PoseInFrame:
    """One planar pose (3,) -> PoseInFrame."""
    return fm.PoseInFrame(timestamp=timestamp(stamp_ns), frame_id=frame_id, pose=planar_pose(pose))


def poses_in_frame(poses: np.ndarray, stamp_ns: int, frame_id: str) -> fm.PosesInFrame:
    """Planar poses (N, 3) -> PosesInFrame (a path, or the particle cloud)."""
    poses = np.asarray(poses, float).reshape(-1, 3)
    c, s = np.cos(poses[:, 2] / 2), np.sin(poses[:, 2] / 2)
    out = [fm.Pose(position=fm.Vector3(x=x, y=y, z=0.0), orientation=fm.Quaternion(x=0.0, y=0.0, z=sz, w=cz))
           for x, y, sz, cz in zip(poses[:, 0].tolist(), poses[:, 1].tolist(), s.tolist(), c.tolist())]
    return fm.PosesInFrame(timestamp=timestamp(stamp_ns), frame_id=frame_id, poses=out)


def frame_transforms(items: Iterable[tuple[int, str, str, np.ndarray, np.ndarray]]) -> fm.FrameTransforms:
    """(stamp [ns], parent, child, translation (3,) [m], rotation quaternion (x, y, z, w)) items ->
    FrameTransforms."""
    out = []
    for stamp_ns, parent, child, t, q in items:
        out.append(fm.FrameTransform(timestamp=timestamp(stamp_ns), parent_frame_id=parent, child_frame_id=child,
                                     translation=fm.Vector3(x=float(t[0]), y=float(t[1]), z=float(t[2])),
                                     rotation=fm.Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))))
    return fm.FrameTransforms(transforms=out)


_XYZ = [fm.PackedElementField(name=n, offset=4 * i, type=fm.PackedElementFieldNumericType.Float32)
        for i, n in enumerate("xyz")]


def point_cloud(points: np.ndarray, stamp_ns: int, frame_id: str) -> fm.PointCloud:
    """Points (N, 3) [m] -> PointCloud of float32 x, y, z (12-byte stride)."""
    data = np.ascontiguousarray(np.asarray(points, float).reshape(-1, 3), np.float32)
    return fm.PointCloud(timestamp=timestamp(stamp_ns), frame_id=frame_id, pose=planar_pose(np.zeros(3)),
                         point_stride=12, fields=_XYZ, data=data.tobytes())


def ellipsoids(centres: np.ndarray, quats: np.ndarray, sizes: np.ndarray, stamp_ns: int, frame_id: str,
               rgba=(0.1, 0.6, 1.0, 0.5), entity: str = "landmarks") -> fm.SceneUpdate:
    """Ellipsoids: centres (N, 3) [m], orientations (N, 4) (x, y, z, w) and diameters (N, 3) [m]
    -> a SceneUpdate replacing entity ``entity`` with N spheres."""
    color = fm.Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])
    spheres = [fm.SpherePrimitive(pose=fm.Pose(position=fm.Vector3(x=c[0], y=c[1], z=c[2]),
                                               orientation=fm.Quaternion(x=q[0], y=q[1], z=q[2], w=q[3])),
                                  size=fm.Vector3(x=s[0], y=s[1], z=s[2]), color=color)
               for c, q, s in zip(np.asarray(centres, float).tolist(), np.asarray(quats, float).tolist(),
                                  np.asarray(sizes, float).tolist())]
    return fm.SceneUpdate(entities=[fm.SceneEntity(timestamp=timestamp(stamp_ns), frame_id=frame_id, id=entity,
                                                   spheres=spheres)])


def spheres(points: np.ndarray, size: float, stamp_ns: int, frame_id: str, rgba=(1.0, 0.5, 0.0, 0.9),
            entity: str = "frontiers") -> fm.SceneUpdate:
    """Points (N, 3) [m] -> a SceneUpdate replacing entity ``entity`` with spheres ``size`` [m] across."""
    pts = np.asarray(points, float).reshape(-1, 3)
    n = len(pts)
    return ellipsoids(pts, np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)), np.full((n, 3), float(size)), stamp_ns, frame_id,
                      rgba, entity)


#: colour of unknown cells (translucent grey), red, green, blue, alpha
UNKNOWN_RGBA = (128, 128, 128, 60)


def occupancy_grid(probability: np.ndarray, known: np.ndarray, origin: np.ndarray, resolution: float,
                   stamp_ns: int, frame_id: str) -> fm.Grid:
    """Occupancy (H, W) in [0, 1] with a known mask (H, W), cell (0, 0)'s corner at ``origin``
    (x, y, θ) [m, rad], ``resolution`` [m/cell] -> Grid, row i at y = origin_y + i·resolution
    (ROS's layout), 5 bytes a cell: ``occupancy`` (int8: -1 unknown, 0-100 percent occupied) and
    ``red``, ``green``, ``blue``, ``alpha`` (uint8: white free to black occupied, unknown
    :data:`UNKNOWN_RGBA`), for the 3D panel's ``rgba-fields`` colour mode."""
    known = np.asarray(known, bool)
    occ = np.where(known, np.rint(100.0 * np.asarray(probability, float)), -1).astype(np.int8)
    h, w = occ.shape
    cells = np.empty((h, w, 5), np.uint8)
    cells[..., 0] = occ.view(np.uint8)
    grey = np.rint(255.0 * (1.0 - np.clip(occ, 0, 100) / 100.0)).astype(np.uint8)
    cells[..., 1:4] = grey[..., None]
    cells[..., 4] = 255
    cells[~known, 1:] = UNKNOWN_RGBA
    u8 = fm.PackedElementFieldNumericType.Uint8
    fields = [fm.PackedElementField(name="occupancy", offset=0, type=fm.PackedElementFieldNumericType.Int8)]
    fields += [fm.PackedElementField(name=n, offset=1 + i, type=u8) for i, n in enumerate(("red", "green", "blue", "alpha"))]
    return fm.Grid(timestamp=timestamp(stamp_ns), frame_id=frame_id, pose=planar_pose(origin), column_count=w,
                   cell_size=fm.Vector2(x=float(resolution), y=float(resolution)), row_stride=5 * w, cell_stride=5,
                   fields=fields, data=cells.tobytes())


#: numpy image layouts of sensor_msgs/Image encodings the RawImage schema shares
_IMAGE_BYTES = {"mono8": 1, "8UC1": 1, "rgb8": 3, "bgr8": 3, "mono16": 2, "16UC1": 2, "rgba8": 4, "bgra8": 4}


def raw_image(image: np.ndarray, encoding: str, stamp_ns: int, frame_id: str) -> fm.RawImage:
    """An image (H, W) or (H, W, C) in ``encoding`` (a sensor_msgs/Image encoding) -> RawImage."""
    img = np.ascontiguousarray(image)
    h, w = img.shape[:2]
    step = w * _IMAGE_BYTES.get(encoding, img.itemsize * (img.shape[2] if img.ndim == 3 else 1))
    return fm.RawImage(timestamp=timestamp(stamp_ns), frame_id=frame_id, width=w, height=h, encoding=encoding,
                       step=step, data=img.tobytes())


def image_points(uv: np.ndarray, stamp_ns: int, rgba=(0.0, 1.0, 0.2, 1.0), size: float = 5.0) -> fm.ImageAnnotations:
    """Pixels (N, 2) (u right, v down) -> ImageAnnotations of one POINTS annotation, stamped like
    the image it belongs to (the Image panel pairs them by timestamp)."""
    color = fm.Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])
    pts = [fm.Point2(x=u, y=v) for u, v in np.asarray(uv, float).reshape(-1, 2).tolist()]
    ann = fm.PointsAnnotation(timestamp=timestamp(stamp_ns), type=fm.PointsAnnotationType.Points, points=pts,
                              outline_color=color, fill_color=color, thickness=size)
    return fm.ImageAnnotations(points=[ann])


def camera_calibration(k: np.ndarray, d: np.ndarray, r: np.ndarray, p: np.ndarray, width: int, height: int,
                       distortion_model: str, stamp_ns: int, frame_id: str) -> fm.CameraCalibration:
    """A camera (K (3, 3), D (n,), R (3, 3), P (3, 4), as in sensor_msgs/CameraInfo) -> CameraCalibration."""
    return fm.CameraCalibration(timestamp=timestamp(stamp_ns), frame_id=frame_id, width=int(width), height=int(height),
                                distortion_model=distortion_model, D=np.ravel(d).astype(float).tolist(),
                                K=np.ravel(k).astype(float).tolist(), R=np.ravel(r).astype(float).tolist(),
                                P=np.ravel(p).astype(float).tolist())


def project_points(points_base: np.ndarray, t_base_cam: np.ndarray, k: np.ndarray, d: np.ndarray,
                   width: int, height: int) -> np.ndarray:
    """Points (N, 3) in base_link [m] -> their pixels (M, 2) in the camera's raw image.

    ``t_base_cam`` (4, 4) is base_link <- the (unrectified) camera optical frame, ``k`` (3, 3) and
    ``d`` its intrinsics and distortion (OpenCV's model, as CameraInfo's plumb_bob). Points behind
    the camera or outside the image are left out.
    """
    import cv2

    pts = np.asarray(points_base, float).reshape(-1, 3)
    t_cam_base = np.linalg.inv(np.asarray(t_base_cam, float).reshape(4, 4))
    cam = pts @ t_cam_base[:3, :3].T + t_cam_base[:3, 3]
    cam = cam[cam[:, 2] > 1e-3]
    if not len(cam):
        return np.zeros((0, 2))
    uv, _ = cv2.projectPoints(cam, np.zeros(3), np.zeros(3), np.asarray(k, float).reshape(3, 3),
                              np.asarray(d, float).ravel())
    uv = uv.reshape(-1, 2)
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < width) & (uv[:, 1] >= 0) & (uv[:, 1] < height)
    return uv[inside]


def chain(transforms: dict[str, tuple[str, np.ndarray, np.ndarray]], base: str, frame: str) -> np.ndarray | None:
    """(4, 4) ``base`` <- ``frame`` composed along ``transforms`` (child -> (parent, translation (3,),
    quaternion (x, y, z, w))), or None when ``frame`` does not lead up to ``base``."""
    from scipy.spatial.transform import Rotation

    out, seen = np.eye(4), set()
    while frame != base:
        if frame not in transforms or frame in seen:
            return None
        seen.add(frame)
        parent, t, q = transforms[frame]
        step = np.eye(4)
        step[:3, :3], step[:3, 3] = Rotation.from_quat(q).as_matrix(), t
        out, frame = step @ out, parent
    return out


# ----------------------------------------------------------------------------- the server
class _ErrorCounter(logging.Handler):
    """Counts the SDK's log records about a client's bad message (it answers the client with a
    status and drops the message)."""

    def __init__(self, counter: Counter):
        super().__init__(logging.WARNING)
        self.counter = counter

    def emit(self, record: logging.LogRecord) -> None:
        if record.getMessage().startswith("Invalid message"):
            self.counter["invalid_message"] += 1
        else:
            self.counter["client_error"] += 1


class _Listener(ServerListener):
    """Keeps count of clients' subscriptions."""

    def __init__(self, lock: threading.Lock):
        self.lock = lock
        self.subscriptions = 0

    def on_subscribe(self, client, channel) -> None:
        with self.lock:
            self.subscriptions += 1

    def on_unsubscribe(self, client, channel) -> None:
        with self.lock:
            self.subscriptions -= 1


class ViewServer:
    """A Foxglove WebSocket server and its channels.

    Args:
        host: address to listen on (``0.0.0.0`` to be reachable from other machines).
        port: TCP port (0: any free one; see :attr:`port`).
        name: the server's name shown by the client.

    Channels are made on first use (:meth:`log`, :meth:`advertise`), from :data:`STREAMS`.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 8765, name: str = "mrslam"):
        self.context = foxglove.Context()
        self.errors: Counter[str] = Counter()
        self._lock = threading.Lock()
        self.listener = _Listener(self._lock)
        self._handler = _ErrorCounter(self.errors)
        sdk_log = logging.getLogger("foxglove")
        sdk_log.addHandler(self._handler)
        sdk_log.setLevel(logging.WARNING)
        sdk_log.propagate = False
        foxglove.set_log_level("WARNING")
        self.server = foxglove.start_server(name=name, host=host, port=port, context=self.context,
                                            server_listener=self.listener)
        self.port = self.server.port
        self.channels: dict[str, object] = {}
        self.sent: Counter[str] = Counter()

    @property
    def client_errors(self) -> dict[str, int]:
        """Bad client messages, by kind (each ignored)."""
        with self._lock:
            return dict(self.errors)

    @property
    def subscriptions(self) -> int:
        """Channel subscriptions of all connected clients."""
        with self._lock:
            return self.listener.subscriptions

    def advertise(self, name: str) -> object:
        """The channel ``name`` (made and advertised on first call); its class comes from the
        pattern of :data:`STREAMS` it matches."""
        ch = self.channels.get(name)
        if ch is None:
            cls = STREAMS.get(name) or STREAMS.get("/{robot}/" + name.split("/", 2)[-1])
            if cls is None:
                raise KeyError(f"no stream {name!r}")
            ch = self.channels[name] = cls(name, context=self.context)
        return ch

    def wants(self, name: str) -> bool:
        """Whether a client subscribes to channel ``name`` (advertising it if new)."""
        return self.advertise(name).has_sinks()

    def log(self, name: str, msg, stamp_ns: int) -> None:
        """Send ``msg`` on channel ``name`` with log time ``stamp_ns`` [ns]."""
        self.advertise(name).log(msg, log_time=int(stamp_ns))
        self.sent[name] += 1

    def close(self) -> None:
        self.server.stop()
        logging.getLogger("foxglove").removeHandler(self._handler)
