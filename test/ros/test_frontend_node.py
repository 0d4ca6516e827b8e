"""The frontend node on a live graph: simulator stereo pairs and camera_info in, observation
clouds in base_link out; images without camera_info are dropped and counted."""

import time

import numpy as np
import pytest

pytestmark = pytest.mark.ros


def test_frontend_node_publishes_observations():
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import PointCloud2

    from mrslam_core.sim.config import SimConfig
    from mrslam_core.sim.simulation import Simulation
    from mrslam_ros.conversions import array_to_image, calibration_to_camera_info, cloud_to_observations
    from mrslam_ros.frontend_node import FrontendNode

    sim = Simulation(SimConfig(world="small"))
    sim.add_robot("robot1", np.array([3.0, 2.0, 0.0]))
    left_cal, right_cal = sim.camera_infos()
    rclpy.init()
    try:
        node = FrontendNode(namespace="robot1", parameter_overrides=[
            Parameter("t_base_cam", value=sim.camera_extrinsic().ravel().tolist())])
        feeder = rclpy.create_node("feeder", namespace="robot1")
        pubs = {k: feeder.create_publisher(t, f"stereo/{k}", 10) for k, t in (
            ("left/image_raw", type(array_to_image(np.zeros((2, 2), np.uint8), "mono8", 0, ""))),
            ("right/image_raw", type(array_to_image(np.zeros((2, 2), np.uint8), "mono8", 0, ""))),
            ("left/camera_info", type(calibration_to_camera_info(left_cal, 0, ""))),
            ("right/camera_info", type(calibration_to_camera_info(left_cal, 0, ""))))}
        clouds = []
        feeder.create_subscription(PointCloud2, "observations", clouds.append, 10)
        ex = SingleThreadedExecutor()
        ex.add_node(node)
        ex.add_node(feeder)
        end = time.time() + 10
        while time.time() < end and feeder.count_subscribers("/robot1/stereo/left/image_raw") == 0:
            ex.spin_once(timeout_sec=0.05)

        def send(frame, with_info=True):
            if with_info:
                pubs["left/camera_info"].publish(calibration_to_camera_info(left_cal, frame.stamp_ns, "robot1/camera_left_optical"))
                pubs["right/camera_info"].publish(calibration_to_camera_info(right_cal, frame.stamp_ns, "robot1/camera_right_optical"))
                for _ in range(3):
                    ex.spin_once(timeout_sec=0.01)
            pubs["left/image_raw"].publish(array_to_image(frame.left, "mono8", frame.stamp_ns, "robot1/camera_left_optical"))
            pubs["right/image_raw"].publish(array_to_image(frame.right, "mono8", frame.stamp_ns, "robot1/camera_right_optical"))
            for _ in range(5):
                ex.spin_once(timeout_sec=0.02)

        sim.set_command("robot1", 0.1, 0.0)
        send(sim.render_stereo("robot1"), with_info=False)  # no camera_info yet: dropped, counted
        assert node.drops["no_camera_info"] == 1
        for _ in range(6):
            sim.run_until(sim.time_ns + int(0.2e9))
            send(sim.render_stereo("robot1"))
        end = time.time() + 5
        while time.time() < end and not clouds:
            ex.spin_once(timeout_sec=0.05)
        assert clouds, dict(node.drops)
        obs = cloud_to_observations(clouds[-1], "robot1")
        assert clouds[-1].header.frame_id == "robot1/base_link" and len(obs) >= 5
        assert np.all(obs.z[:, 0] > 0)  # in front of the robot
        assert obs.descriptors.shape[1] == 64  # U-SURF
    finally:
        rclpy.shutdown()
        sim.close()


@pytest.mark.parametrize("image_qos", ["reliable", "best_effort"])
def test_a_best_effort_camera_is_counted_or_heard(image_qos):
    """A camera driver publishing best-effort (ROS's sensor-data QoS) cannot match a reliable
    subscription: the node counts it (``incompatible_qos``); with ``image_qos: best_effort`` its
    images arrive."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Image

    from mrslam_ros.conversions import array_to_image
    from mrslam_ros.frontend_node import FrontendNode

    rclpy.init()
    try:
        node = FrontendNode(namespace="robot1", parameter_overrides=[Parameter("image_qos", value=image_qos)])
        camera = rclpy.create_node("camera", namespace="robot1")
        pubs = [camera.create_publisher(Image, f"stereo/{side}/image_raw", qos_profile_sensor_data) for side in ("left", "right")]
        ex = SingleThreadedExecutor()
        ex.add_node(node)
        ex.add_node(camera)
        end = time.time() + 10
        while time.time() < end and not (node.drops.get("incompatible_qos") or node.drops.get("no_camera_info")):
            stamp = int(time.time() * 1e9)
            for pub in pubs:
                pub.publish(array_to_image(np.zeros((4, 6), np.uint8), "mono8", stamp, "cam"))
            ex.spin_once(timeout_sec=0.05)
        if image_qos == "reliable":
            assert node.drops["incompatible_qos"] >= 1 and not node.drops.get("no_camera_info")
        else:  # heard (and dropped for want of camera_info, the next thing it checks)
            assert node.drops["no_camera_info"] >= 1 and not node.drops.get("incompatible_qos")
    finally:
        rclpy.shutdown()
