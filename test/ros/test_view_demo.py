"""`mrslam demo --view` as a user runs it: a WebSocket client connects to the running team, lists
the advertised channels and receives a message of every stream in its schema; garbage it sends
is answered and counted, and the node goes on and stops cleanly."""

import json
import socket
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("foxglove", reason="foxglove-sdk (the `view` extra) is not installed")
pytest.importorskip("websockets", reason="websockets (the `test` extra) is not installed")

from foxglove_client import wait_for_server, watch  # noqa: E402

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.live]

BIN = Path(sys.executable).parent
ROBOTS = ("robot1", "robot2")
SCHEMAS = {"/tf": "FrameTransforms", "/map": "Grid", "/slam/landmarks": "PointCloud", "/slam/particles": "PosesInFrame",
           "/exploration/frontiers": "SceneUpdate"}
PER_ROBOT = {"pose": "PoseInFrame", "path": "PosesInFrame", "ground_truth": "PoseInFrame",
             "ground_truth_path": "PosesInFrame", "goal": "PoseInFrame", "plan": "PosesInFrame", "image": "RawImage",
             "image_points": "ImageAnnotations", "camera_calibration": "CameraCalibration"}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_client_watches_a_running_demo(tmp_path):
    port = _free_port()
    out = tmp_path / "run"
    # 20 simulated s at 0.8 of real time (two robots keep up at 0.8 on 2 cores, config/demo_faults.yaml):
    # every stream has published by then (with 12 s, on a machine 1.5x slower, the demo ended and
    # closed the view before the client had received every stream)
    proc = subprocess.Popen([str(BIN / "mrslam"), "demo", "--robots", "2", "--seconds", "20", "--rtf", "0.8",
                             "--world", "small", "--view", "--view-port", str(port), "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        assert wait_for_server(port, 120), "no view server"
        schemas = dict(SCHEMAS) | {f"/{r}/{k}": v for r in ROBOTS for k, v in PER_ROBOT.items()}
        channels, received, replies = watch(port, set(schemas), timeout=120, garbage=["{not json", b"\x09"])
        output, _ = proc.communicate(timeout=600)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, output[-3000:]
    assert set(schemas) <= set(channels), sorted(set(schemas) - set(channels))
    for name, schema in schemas.items():
        assert channels[name]["schemaName"] == f"foxglove.{schema}", name
    assert set(schemas) <= set(received), sorted(set(schemas) - set(received))
    assert received["/robot1/image"].width > 0 and len(received["/robot1/image"].data) > 0
    assert received["/map"].column_count > 0 and received["/slam/landmarks"].point_stride == 12
    assert len(replies) == 2
    report = json.loads((out / "report.json").read_text())
    assert report["exit_codes"]["view"] == 0 and report["failed_nodes"] == []
    view = report["diagnostics"]["/view"]
    assert view["drops.client_invalid_message"] == 2 and view["robots"] == 2
    assert report["cpu_s"]["view"] > 0
    assert report["explored_fraction"] is not None  # /map was recorded beside the viewer's subscription
