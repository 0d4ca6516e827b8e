"""The Foxglove view: exact messages from arrays, a WebSocket client on a server in this process,
and the view node on a live graph (a client receives each stream in its schema; bad client
messages are answered, counted and survive)."""

import threading
import time

import numpy as np
import pytest

pytest.importorskip("foxglove", reason="foxglove-sdk (the `view` extra) is not installed")
pytest.importorskip("websockets", reason="websockets (the `test` extra) is not installed")

from foxglove_client import decoder, watch  # noqa: E402

from mrslam_ros import foxglove_view as fv  # noqa: E402

# base_link <- left optical frame of the simulator's camera head (z forward = base x)
T_BASE_CAM = np.array([[0.0, 0.0, 1.0, 0.12], [-1.0, 0.0, 0.0, 0.06], [0.0, -1.0, 0.0, 0.45], [0.0, 0.0, 0.0, 1.0]])
K = np.array([[300.0, 0.0, 160.0], [0.0, 300.0, 120.0], [0.0, 0.0, 1.0]])


def _decode(msg):
    """Encode a foxglove message and decode it with its own advertised protobuf schema."""
    schema = type(msg).get_schema()
    import base64

    channel = {"encoding": "protobuf", "schemaEncoding": "protobuf", "schemaName": schema.name,
               "schema": base64.b64encode(schema.data).decode()}
    return decoder(channel)(msg.encode())


def test_occupancy_grid_keeps_ros_layout_and_values():
    prob = np.array([[0.0, 0.25, 1.0], [0.5, 0.5, 0.9]])
    known = np.array([[True, True, True], [False, True, True]])
    g = _decode(fv.occupancy_grid(prob, known, np.array([-2.0, 3.0, 0.0]), 0.05, 1_500_000_000, "map"))
    assert (g.column_count, g.row_stride, g.cell_stride) == (3, 15, 5)
    assert g.cell_size.x == g.cell_size.y == 0.05 and g.pose.position.x == -2.0 and g.pose.position.y == 3.0
    assert (g.timestamp.seconds, g.timestamp.nanos) == (1, 500_000_000)
    cells = np.frombuffer(g.data, np.uint8).reshape(6, 5)
    assert cells[:, 0].view(np.int8).tolist() == [0, 25, 100, -1, 50, 90]
    assert cells[:, 1].tolist() == [255, 191, 0, 128, 128, 25] and cells[:, 4].tolist() == [255, 255, 255, 60, 255, 255]
    assert [(f.name, f.offset) for f in g.fields] == [("occupancy", 0), ("red", 1), ("green", 2), ("blue", 3), ("alpha", 4)]


def test_poses_cloud_and_transforms_are_exact():
    p = _decode(fv.poses_in_frame(np.array([[1.0, 2.0, np.pi / 2], [0.0, 0.0, -np.pi]]), 7, "map"))
    assert p.frame_id == "map" and len(p.poses) == 2
    assert p.poses[0].orientation.z == pytest.approx(np.sin(np.pi / 4)) and p.poses[0].position.y == 2.0
    c = _decode(fv.point_cloud(np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]), 0, "map"))
    assert c.point_stride == 12 and np.frombuffer(c.data, np.float32).tolist() == [1, 2, 3, 4, 5, 6]
    t = _decode(fv.frame_transforms([(3, "a", "b", np.array([1.0, 0.0, 0.5]), np.array([0.0, 0.0, 0.0, 1.0]))]))
    assert t.transforms[0].child_frame_id == "b" and t.transforms[0].translation.z == 0.5


def test_observed_points_land_on_their_pixels():
    # a point 1.88 m straight ahead of the camera is at the principal point; one 0.5 m to the
    # left of the optical axis at that depth is 300·0.5/1.88 px left of it; one behind is left out
    pts = np.array([[2.0, 0.06, 0.45], [2.0, 0.56, 0.45], [-1.0, 0.0, 0.0]])
    uv = fv.project_points(pts, T_BASE_CAM, K, np.zeros(5), 320, 240)
    np.testing.assert_allclose(uv, [[160.0, 120.0], [160.0 - 300.0 * 0.5 / 1.88, 120.0]], atol=1e-9)
    ann = _decode(fv.image_points(uv, 42))
    assert len(ann.points) == 1 and len(ann.points[0].points) == 2 and ann.points[0].timestamp.nanos == 42


def test_transform_chain_composes_and_refuses_a_broken_one():
    half = np.sqrt(0.5)
    tf = {"cam": ("mount", np.array([0.0, 0.0, 0.1]), np.array([0.0, 0.0, half, half])),
          "mount": ("base", np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 0.0, 1.0]))}
    t = fv.chain(tf, "base", "cam")
    np.testing.assert_allclose(t[:3, 3], [1.0, 0.0, 0.1], atol=1e-12)
    np.testing.assert_allclose(t[:3, 0], [0.0, 1.0, 0.0], atol=1e-12)  # turned 90° about z
    assert fv.chain(tf, "odom", "cam") is None
    assert fv.chain({"a": ("b", np.zeros(3), np.array([0, 0, 0, 1.0])), "b": ("a", np.zeros(3), np.array([0, 0, 0, 1.0]))},
                    "base", "a") is None  # a loop


def test_server_advertises_streams_and_survives_bad_client_messages():
    server = fv.ViewServer(port=0)
    try:
        names = fv.channel_names(["robot1"])
        for name in names:
            server.advertise(name)
        stop = threading.Event()

        def feed():
            while not stop.is_set():
                if server.wants("/map"):
                    server.log("/map", fv.occupancy_grid(np.full((2, 2), 0.5), np.ones((2, 2), bool), np.zeros(3), 0.1, 5, "map"), 5)
                if server.wants("/robot1/pose"):
                    server.log("/robot1/pose", fv.pose_in_frame(np.array([1.0, 2.0, 0.0]), 5, "map"), 5)
                time.sleep(0.02)

        worker = threading.Thread(target=feed)
        worker.start()
        try:
            garbage = ["not json", '{"op": "subscribe"}', b"\x07garbage", b"\x01\x00"]
            channels, received, replies = watch(server.port, {"/map", "/robot1/pose"}, timeout=20, garbage=garbage)
        finally:
            stop.set()
            worker.join()
        assert set(channels) == set(names)
        assert channels["/map"]["schemaName"] == "foxglove.Grid"
        assert channels["/robot1/image_points"]["schemaName"] == "foxglove.ImageAnnotations"
        assert received["/robot1/pose"].pose.position.y == 2.0
        assert len(replies) == len(garbage) and all(r["level"] == 2 for r in replies)
        deadline = time.time() + 5
        while time.time() < deadline and sum(server.client_errors.values()) < len(garbage):
            time.sleep(0.05)
        assert server.client_errors == {"invalid_message": len(garbage)}
        assert not server.wants("/map")  # the client left: nothing is built any more
    finally:
        server.close()


@pytest.mark.ros
def test_view_node_streams_a_graph_to_a_client():
    import rclpy
    from geometry_msgs.msg import PoseWithCovarianceStamped
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import CameraInfo, Image, PointCloud2
    from tf2_msgs.msg import TFMessage

    from mrslam_core.frontend.camera import CameraCalibration
    from mrslam_core.types import ObservationSet
    from mrslam_ros.conversions import (
        array_to_image,
        calibration_to_camera_info,
        matrix_transform_msg,
        observations_to_cloud,
        pose_with_covariance,
    )
    from mrslam_ros.qos import TF_STATIC
    from mrslam_ros.view_node import ViewNode

    rclpy.init()
    stop = threading.Event()
    try:
        node = ViewNode(parameter_overrides=[Parameter("robots", value=["robot1"]), Parameter("port", value=0)])
        probe = rclpy.create_node("probe")
        tf_static = probe.create_publisher(TFMessage, "/tf_static", TF_STATIC)
        tf_static.publish(TFMessage(transforms=[matrix_transform_msg(T_BASE_CAM, 0, "robot1/base_link", "robot1/cam")]))
        info_pub = probe.create_publisher(CameraInfo, "/robot1/stereo/left/camera_info", 5)
        image_pub = probe.create_publisher(Image, "/robot1/stereo/left/image_raw", 5)
        obs_pub = probe.create_publisher(PointCloud2, "/robot1/observations", 5)
        pose_pub = probe.create_publisher(PoseWithCovarianceStamped, "/robot1/pose", 5)
        cal = CameraCalibration(width=320, height=240, K=K, D=np.zeros(5), R=np.eye(3),
                                P=np.hstack([K, np.zeros((3, 1))]), distortion_model="plumb_bob")
        image = np.tile(np.arange(320, dtype=np.uint8), (240, 1))
        obs = ObservationSet("robot1", 2_000_000_000, np.array([[2.0, 0.06, 0.45]]), np.tile(np.eye(3) * 1e-4, (1, 1, 1)))
        ex = SingleThreadedExecutor()
        ex.add_node(node)
        ex.add_node(probe)

        def spin():
            while not stop.is_set():
                info_pub.publish(calibration_to_camera_info(cal, 2_000_000_000, "robot1/cam"))
                image_pub.publish(array_to_image(image, "mono8", 2_000_000_000, "robot1/cam"))
                obs_pub.publish(observations_to_cloud(obs, "robot1/base_link"))
                pose_pub.publish(pose_with_covariance(np.array([1.0, -1.0, 0.3]), np.eye(3) * 1e-4, 2_000_000_000, "map"))
                for _ in range(5):
                    ex.spin_once(timeout_sec=0.01)

        worker = threading.Thread(target=spin)
        worker.start()
        want = {"/robot1/image", "/robot1/image_points", "/robot1/camera_calibration", "/robot1/pose", "/tf"}
        channels, received, _ = watch(node.server.port, want, timeout=30, garbage=["{broken"])
        assert want <= set(received), sorted(want - set(received))
        img = received["/robot1/image"]
        assert (img.width, img.height, img.encoding) == (320, 240, "mono8") and img.data == image.tobytes()
        pts = received["/robot1/image_points"].points[0].points
        assert [(p.x, p.y) for p in pts] == [pytest.approx((160.0, 120.0))]
        assert received["/robot1/camera_calibration"].K[0] == 300.0
        assert received["/robot1/pose"].pose.position.x == 1.0
        assert received["/tf"].transforms[0].child_frame_id == "robot1/cam"
        assert channels["/slam/landmarks"]["schemaName"] == "foxglove.PointCloud"
        deadline = time.time() + 3
        while time.time() < deadline and node.diag.drops.get("client_invalid_message", 0) < 1:
            node.report()
            time.sleep(0.05)
        assert node.diag.drops["client_invalid_message"] == 1
    finally:
        stop.set()
        if "worker" in locals():
            worker.join()
        rclpy.shutdown()
