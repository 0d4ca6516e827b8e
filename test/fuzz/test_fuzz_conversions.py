"""Property-based fuzzing of the message conversions (hypothesis), with messages built by hand.

Decoders get arbitrary layouts and contents (PointCloud2 fields with any offset, datatype and
count, any point_step/row_step/width/height, truncated or padded data, big-endian flags; images
with any encoding, size, step and data length; non-finite poses, transforms, grids and scans);
encoders get arrays of the wrong shape. Property: the result is well formed, or the conversion
raises ConversionError (a ValueError) — never another exception.
"""

import numpy as np
import pytest

pytest.importorskip("sensor_msgs", reason="ROS message types (the `ros` extra) are not installed")

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseWithCovarianceStamped, TransformStamped
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from nav_msgs.msg import OccupancyGrid, Odometry
from sensor_msgs.msg import CameraInfo, Image, LaserScan, PointCloud2, PointField

from mrslam_core.types import ObservationSet
from mrslam_ros import conversions as cv
from mrslam_ros.conversions import ConversionError

SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
NAMES = ["x", "y", "z", "cxx", "cxy", "cxz", "cyy", "cyz", "czz", "track_id", "descriptor", "rgb"]
floats = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(-10, 10))
u32 = st.integers(0, 2**32 - 1)


def valid_cloud(b: int = 3, d: int = 4) -> PointCloud2:
    rng = np.random.default_rng(b)
    a = rng.standard_normal((b, 3, 3))
    obs = ObservationSet("r", 123, rng.standard_normal((b, 3)), a @ a.transpose(0, 2, 1) + np.eye(3),
                         rng.standard_normal((b, d)).astype(np.float32), np.arange(b))
    return cv.observations_to_cloud(obs, "r/base_link")


def check_observations(obs: ObservationSet, msg: PointCloud2) -> None:
    n = msg.width * msg.height
    assert obs.z.shape == (n, 3) and obs.cov.shape == (n, 3, 3) and obs.track_ids.shape == (n,)
    assert obs.descriptors.shape[0] == n and np.isfinite(obs.z).all() and np.isfinite(obs.cov).all()


def decode_cloud(msg: PointCloud2) -> None:
    try:
        obs = cv.cloud_to_observations(msg, "r")
    except ConversionError:
        return
    check_observations(obs, msg)


@SETTINGS
@given(
    fields=st.lists(st.builds(PointField, name=st.sampled_from(NAMES), offset=st.integers(0, 80),
                              datatype=st.integers(0, 9), count=st.integers(0, 12)), max_size=14),
    width=st.integers(0, 12), height=st.integers(0, 3), point_step=st.integers(0, 90),
    row_step=st.integers(0, 1200), data=st.binary(max_size=2500), big=st.booleans(),
)
def test_arbitrary_point_cloud_layouts(fields, width, height, point_step, row_step, data, big):
    msg = PointCloud2(height=height, width=width, fields=fields, is_bigendian=big,
                      point_step=point_step, row_step=row_step, data=data)
    decode_cloud(msg)


@SETTINGS
@given(
    b=st.integers(0, 6), d=st.integers(0, 6),
    mutation=st.sampled_from(["truncate", "pad", "offset", "datatype", "count", "point_step",
                              "row_step", "width", "height", "drop", "nan", "duplicate"]),
    which=st.integers(0, 20), value=st.integers(0, 2**32 - 1), cut=st.integers(0, 400),
)
def test_mutated_observation_clouds(b, d, mutation, which, value, cut):
    msg = valid_cloud(b, d)
    f = msg.fields[which % len(msg.fields)]
    if mutation == "truncate":
        msg.data = bytes(msg.data)[: max(len(msg.data) - cut, 0)]
    elif mutation == "pad":
        msg.data = bytes(msg.data) + bytes(cut)
    elif mutation == "offset":
        f.offset = value
    elif mutation == "datatype":
        f.datatype = value % 256
    elif mutation == "count":
        f.count = value
    elif mutation == "point_step":
        msg.point_step = value % 4096
    elif mutation == "row_step":
        msg.row_step = value
    elif mutation == "width":
        msg.width = value
    elif mutation == "height":
        msg.height = value % 8
    elif mutation == "drop":
        msg.fields = [g for g in msg.fields if g is not f]
    elif mutation == "nan" and b:
        raw = bytearray(msg.data)
        raw[f.offset : f.offset + 4] = np.float32(np.nan).tobytes()
        msg.data = bytes(raw)
    elif mutation == "duplicate":
        msg.fields = list(msg.fields) + [PointField(name=f.name, offset=value % 64, datatype=7, count=1)]
    decode_cloud(msg)


def test_valid_clouds_still_decode():
    for b, d in ((0, 0), (1, 0), (5, 8)):
        obs = cv.cloud_to_observations(valid_cloud(b, d), "r")
        assert obs.z.shape == (b, 3) and obs.descriptors.shape == (b, d)


@SETTINGS
@given(
    encoding=st.sampled_from(["mono8", "mono16", "rgb8", "bgr8", "rgba8", "bgra8", "32FC1", "", "yuv422"]),
    height=st.integers(0, 9), width=st.integers(0, 9), step=st.integers(0, 40),
    data=st.binary(max_size=400), big=st.integers(0, 1),
)
def test_arbitrary_images(encoding, height, width, step, data, big):
    msg = Image(height=height, width=width, encoding=encoding, is_bigendian=big, step=step, data=data)
    try:
        arr = cv.image_to_array(msg)
    except ConversionError:
        return
    assert arr.shape[:2] == (height, width)


@SETTINGS
@given(arr=hnp.arrays(st.sampled_from([np.uint8, np.uint16, np.float64, np.bool_]),
                      hnp.array_shapes(min_dims=0, max_dims=4, min_side=0, max_side=4)),
       encoding=st.sampled_from(["mono8", "mono16", "rgb8", "bgra8", "jpeg"]))
def test_array_to_image_with_any_shape(arr, encoding):
    try:
        msg = cv.array_to_image(arr, encoding, 5, "cam")
    except ConversionError:
        return
    back = cv.image_to_array(msg) if msg.height and msg.width else None
    if back is not None:
        assert back.size == arr.size


@SETTINGS
@given(k=st.lists(floats, min_size=9, max_size=9), d=st.lists(floats, max_size=8),
       r=st.lists(floats, min_size=9, max_size=9), p=st.lists(floats, min_size=12, max_size=12),
       width=u32, height=u32, model=st.sampled_from(["plumb_bob", "equidistant", "", "fancy"]))
def test_arbitrary_camera_info(k, d, r, p, width, height, model):
    msg = CameraInfo(width=width, height=height, distortion_model=model, k=k, d=d, r=r, p=p)
    try:
        cal = cv.camera_info_to_calibration(msg)
    except ConversionError:
        return
    assert np.isfinite(cal.K).all()


@SETTINGS
@given(values=st.lists(floats, min_size=7, max_size=7), cov=st.lists(floats, min_size=36, max_size=36))
def test_poses_transforms_and_odometry(values, cov):
    x, y, z, qx, qy, qz, qw = values
    odom = Odometry()
    odom.pose.pose.position.x, odom.pose.pose.position.y, odom.pose.pose.position.z = x, y, z
    o = odom.pose.pose.orientation
    o.x, o.y, o.z, o.w = qx, qy, qz, qw
    odom.pose.covariance = cov
    pwc = PoseWithCovarianceStamped()
    pwc.pose = odom.pose
    tf = TransformStamped()
    tf.transform.translation.x, tf.transform.translation.y = x, y
    tf.transform.rotation = o
    for fn, msg in ((cv.odometry_to_pose, odom), (cv.pose_with_covariance_to_pose, pwc), (cv.transform_to_pose, tf)):
        try:
            out = fn(msg)
        except ConversionError:
            continue
        pose = out[-1] if fn is cv.transform_to_pose else out[1]
        assert pose.shape == (3,) and np.isfinite(pose).all()


@SETTINGS
@given(ranges=st.lists(floats, max_size=20), intens=st.lists(floats, max_size=20),
       angle_min=floats, inc=floats, rmin=floats, rmax=floats)
def test_arbitrary_laser_scans(ranges, intens, angle_min, inc, rmin, rmax):
    f32 = lambda v: float(np.float32(v)) if abs(v) < 3e38 or not np.isfinite(v) else 0.0
    msg = LaserScan(angle_min=f32(angle_min), angle_increment=f32(inc), range_min=f32(rmin),
                    range_max=f32(rmax), ranges=[f32(v) for v in ranges], intensities=[f32(v) for v in intens])
    try:
        scan = cv.laser_to_scan(msg)
    except ConversionError:
        return
    assert np.isfinite(scan.bearings).all() and np.isfinite(scan.ranges).all()


@SETTINGS
@given(h=st.integers(0, 6), w=st.integers(0, 6), data=st.lists(st.integers(-128, 127), max_size=40),
       res=floats, ox=floats, qz=floats)
def test_arbitrary_occupancy_grids(h, w, data, res, ox, qz):
    msg = OccupancyGrid(data=data)
    msg.info.height, msg.info.width, msg.info.resolution = h, w, float(np.float32(res)) if abs(res) < 3e38 or not np.isfinite(res) else 1.0
    msg.info.origin.position.x, msg.info.origin.orientation.z = ox, qz
    try:
        prob, known, origin, resolution = cv.occupancy_to_arrays(msg)
    except ConversionError:
        return
    assert prob.shape == known.shape == (h, w) and resolution > 0 and np.isfinite(origin).all()
    assert ((prob >= 0) & (prob <= 1)).all()


@SETTINGS
@given(pairs=st.lists(st.tuples(st.text(max_size=5), st.text(max_size=8)), max_size=6))
def test_arbitrary_diagnostics(pairs):
    msg = DiagnosticArray(status=[DiagnosticStatus(name="n", values=[KeyValue(key=k, value=v) for k, v in pairs])])
    out = cv.diagnostics_to_counters(msg)
    assert set(out["n"]) <= {k for k, _ in pairs}


shapes = hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=4)


@SETTINGS
@given(pose=hnp.arrays(np.float64, shapes, elements=floats), cov=hnp.arrays(np.float64, shapes, elements=floats),
       ns=st.integers(-(2**70), 2**70))
def test_encoders_reject_wrong_shapes(pose, cov, ns):
    calls = [
        lambda: cv.ns_to_stamp(ns),
        lambda: cv.pose_to_msg(pose),
        lambda: cv.pose_with_covariance(pose, cov, 0, "map"),
        lambda: cv.pose_to_odometry(pose, cov, 0, "odom", "base_link"),
        lambda: cv.transform_msg(pose, 0, "map", "odom"),
        lambda: cv.pose_array_msg(pose, 0, "map"),
        lambda: cv.path_msg(pose, np.zeros(len(pose) if pose.ndim else 0, np.int64), "map"),
        lambda: cv.log_odds_to_occupancy(pose, np.zeros(2), 0.1, 0),
        lambda: cv.landmark_markers(pose, cov, 0),
    ]
    for call in calls:
        try:
            call()
        except ConversionError:
            pass


@SETTINGS
@given(b=st.integers(0, 4), dim=st.sampled_from([2, 3]))
def test_observations_to_cloud_of_any_dimension(b, dim):
    obs = ObservationSet("r", 1, np.zeros((b, dim)), np.broadcast_to(np.eye(dim), (b, dim, dim)))
    try:
        msg = cv.observations_to_cloud(obs, "f")
    except ConversionError:
        assert dim != 3
        return
    assert dim == 3 and cv.cloud_to_observations(msg, "r").z.shape == (b, 3)


def test_regressions_found_by_fuzzing():
    bad = [
        lambda: cv.array_to_image(np.zeros(4, np.uint8), "mono8", 0, "c"),  # IndexError before
        lambda: cv.array_to_image(np.zeros((1, 1, 1, 0), np.uint8), "mono8", 0, "c"),  # bad Image before
        lambda: cv.ns_to_stamp(2**63),  # AssertionError of builtin_interfaces/Time before
        lambda: cv.pose_to_msg(np.zeros(2)),  # IndexError before
        lambda: cv.pose_with_covariance(np.zeros(3), np.zeros(3), 0, "map"),  # numpy ValueError before
        lambda: cv.path_msg(np.array(0.0), np.zeros(0), "map"),  # TypeError before
        lambda: cv.landmark_markers(np.zeros(4), np.zeros((1, 3, 3)), 0),  # numpy ValueError before
        lambda: cv.observations_to_cloud(ObservationSet("r", 1, np.zeros((1, 2)), np.eye(2)[None]), "f"),
        lambda: cv.laser_to_scan(LaserScan(angle_increment=float("inf"), ranges=[1.0], range_max=5.0)),
    ]
    for call in bad:
        with pytest.raises(ConversionError):
            call()
    assert len(cv.path_msg(np.array([]), [], "map").poses) == 0  # an empty path is still fine
