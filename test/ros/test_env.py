"""The generated interface install is found, and a node process started from a bare environment
imports tf2_msgs from it and round-trips a TFMessage (type support libraries loaded from there)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from mrslam_ros.env import (
    PREFIX_VARIABLE,
    ensure_interfaces,
    interfaces_prefix,
    node_env,
    python_dir,
)

pytestmark = pytest.mark.ros

CHILD = textwrap.dedent(
    """
    import rclpy, tf2_msgs
    from tf2_msgs.msg import TFMessage
    from geometry_msgs.msg import TransformStamped
    rclpy.init()
    node = rclpy.create_node("env_probe")
    got = []
    node.create_subscription(TFMessage, "/env_probe_tf", got.append, 10)
    pub = node.create_publisher(TFMessage, "/env_probe_tf", 10)
    t = TransformStamped(child_frame_id="robot7/odom")
    for _ in range(100):
        pub.publish(TFMessage(transforms=[t]))
        rclpy.spin_once(node, timeout_sec=0.05)
        if got:
            break
    maps = sorted({l.split()[-1] for l in open("/proc/self/maps") if "libtf2_msgs__rosidl_typesupport_c" in l})
    print(tf2_msgs.__file__)
    print(maps[0] if maps else "none")
    print(got[0].transforms[0].child_frame_id if got else "nothing")
    """
)


def test_interfaces_are_installed_and_importable():
    prefix = interfaces_prefix()
    assert prefix is not None and (python_dir(prefix) / "tf2_msgs" / "msg").is_dir()
    assert (prefix / "share" / "tf2_msgs" / "package.xml").is_file()
    ensure_interfaces()  # no error
    env = node_env(base={"PYTHONPATH": "/x"}, extra={"A": "1"})
    assert env["PYTHONPATH"].split(os.pathsep) == [str(python_dir(prefix)), "/x"]
    assert env["LD_LIBRARY_PATH"].split(os.pathsep)[0] == str(prefix / "lib")
    assert env["AMENT_PREFIX_PATH"].split(os.pathsep)[:2] == [str(prefix), sys.prefix]
    assert env["A"] == "1" and env["PYTHONUNBUFFERED"] == "1"


def test_missing_install_is_reported(monkeypatch, tmp_path):
    monkeypatch.setenv(PREFIX_VARIABLE, str(tmp_path / "nowhere"))
    assert interfaces_prefix() is None
    assert "PYTHONPATH" not in node_env(base={})


def test_bare_environment_child_uses_the_generated_install():
    """A child with none of this process's ROS variables (no bootstrapper flag, no LD_LIBRARY_PATH)."""
    prefix = interfaces_prefix()
    bare = {k: os.environ[k] for k in ("PATH", "HOME", "ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE") if k in os.environ}
    proc = subprocess.run([sys.executable, "-c", CHILD], env=node_env(base=bare), capture_output=True, text=True,
                          timeout=60, check=False)
    assert proc.returncode == 0, proc.stderr
    module, lib, frame = proc.stdout.split()
    assert module.startswith(str(python_dir(prefix)))
    assert lib.startswith(str(prefix / "lib"))
    assert frame == "robot7/odom"
