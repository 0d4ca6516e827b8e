"""``mrslam launch``: processes with names, namespaces and params; a failing node or Ctrl-C stops all.

The nodes are :mod:`launch_dummy` (beside this file), started through PYTHONPATH.
"""

from __future__ import annotations

import io
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from mrslam_core.configio import ConfigError, from_dict
from mrslam_ros.launch import LaunchConfig, Launcher, NodeSpec

pytestmark = pytest.mark.ros
HERE = Path(__file__).resolve().parent


@pytest.fixture(autouse=True)
def dummy_on_path(monkeypatch):
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(p for p in (str(HERE), os.environ.get("PYTHONPATH", "")) if p))


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def _pids(text: str) -> dict[str, int]:
    return {m.group(1): int(m.group(2)) for m in re.finditer(r"^\[(\S+)\] up pid=(\d+)", text, re.MULTILINE)}


def test_config_schema_and_command(tmp_path):
    (tmp_path / "extra.yaml").write_text("{}")
    cfg = from_dict(LaunchConfig, {"use_sim_time": True, "nodes": [
        {"module": "m.a", "name": "a", "namespace": "/robot1/", "params": {"x": {"y": 2}, "z": None},
         "params_files": ["extra.yaml"], "remap": {"obs": "observations"}}]})
    launcher = Launcher(cfg, base_dir=tmp_path)
    cmd = launcher.command(cfg.nodes[0])
    assert cmd[1:5] == ["-m", "m.a", "--ros-args", "-r"]
    assert "__node:=a" in cmd and "__ns:=/robot1" in cmd and "obs:=observations" in cmd
    files = [cmd[i + 1] for i, c in enumerate(cmd) if c == "--params-file"]
    assert files[0] == str(tmp_path / "extra.yaml")
    params = yaml.safe_load(Path(files[1]).read_text())
    assert params == {"/**": {"ros__parameters": {"x": {"y": 2}, "use_sim_time": True}}}  # None dropped
    launcher.stop()
    with pytest.raises(ConfigError, match="unknown key nodes\\[0\\].modul"):
        from_dict(LaunchConfig, {"nodes": [{"modul": "m", "name": "a"}]})
    with pytest.raises(ConfigError, match="unique"):
        from_dict(LaunchConfig, {"nodes": [{"module": "m", "name": "a"}, {"module": "m", "name": "a"}]})
    with pytest.raises(ConfigError, match="not found"):
        Launcher(LaunchConfig([NodeSpec("m", "a", params_files=["nope.yaml"])]), base_dir=tmp_path).start()


def test_failing_node_stops_the_others(tmp_path):
    cfg = LaunchConfig(nodes=[
        NodeSpec("launch_dummy", "talker", "robot1", {"exit_after": 2.0, "exit_code": 3, "greeting": "hi there"}),
        NodeSpec("launch_dummy", "listener", "robot2"),
        NodeSpec("launch_dummy", "stubborn", params={"stubborn": True}, use_sim_time=False),
    ], use_sim_time=True, log_dir=str(tmp_path / "logs"), stop_timeout=1.5)
    log = io.StringIO()
    launcher = Launcher(cfg, log=log)
    launcher.start()
    t0 = time.monotonic()
    failed = launcher.wait(timeout=30)
    assert failed == ["robot1/talker"]
    assert launcher.exited()["robot1/talker"] == 3
    codes = launcher.stop()
    elapsed = time.monotonic() - t0
    text = log.getvalue()
    assert codes["robot2/listener"] in (0, -signal.SIGINT, 130)  # stopped by the first signal
    assert codes["stubborn"] == -signal.SIGKILL  # ignored SIGINT and SIGTERM: 2 × 1.5 s, then killed
    assert elapsed < 30
    pids = _pids(text)
    assert set(pids) == {"robot1/talker", "robot2/listener", "stubborn"}
    assert not any(_alive(p) for p in pids.values())
    # names, namespaces and params arrive; lines are prefixed and also kept per node
    assert "[robot1/talker] up" in text and "fqn=/robot1/talker sim=True greeting=hi there" in text
    assert "fqn=/robot2/listener sim=True" in text and "fqn=/stubborn sim=False" in text
    assert "[robot1/talker] exiting with 3" in text
    assert "exiting with 3" in (tmp_path / "logs" / "robot1_talker.log").read_text()
    assert "interrupted" in (tmp_path / "logs" / "robot2_listener.log").read_text()


@pytest.mark.parametrize("sigint_ignored", [False, True])
def test_cli_ctrl_c_stops_every_node(tmp_path, sigint_ignored):
    # sigint_ignored: started as a background job of a non-interactive shell (`cmd &`), which
    # passes SIGINT on ignored
    cfg = tmp_path / "launch.yaml"
    # a long stop_timeout: a node that ignored the SIGINT would be sent SIGTERM only after it, and
    # on a loaded machine (a CI run: 4.1 s against a 2 s timeout) rclpy's exit can take seconds
    cfg.write_text(yaml.safe_dump({"stop_timeout": 15.0, "nodes": [
        {"module": "launch_dummy", "name": "a", "namespace": "robot1"},
        {"module": "launch_dummy", "name": "b", "namespace": "robot2"}]}))
    ignore = (lambda: signal.signal(signal.SIGINT, signal.SIG_IGN)) if sigint_ignored else None
    proc = subprocess.Popen([sys.executable, "-m", "mrslam_ros.cli", "launch", str(cfg)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, preexec_fn=ignore)
    lines: list[str] = []
    end = time.monotonic() + 30
    while time.monotonic() < end and len(_pids("".join(lines))) < 2:
        line = proc.stdout.readline()  # type: ignore[union-attr]
        if not line:
            break
        lines.append(line)
    pids = _pids("".join(lines))
    assert set(pids) == {"robot1/a", "robot2/b"}, "".join(lines)
    time.sleep(0.5)  # let both finish writing their first line (a signal inside print() is a traceback)
    t0 = time.monotonic()
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 0, out
    assert time.monotonic() - t0 < 15.0  # the first signal (SIGINT) was enough: no SIGTERM after 15 s
    assert not any(_alive(p) for p in pids.values())
    assert "[robot1/a] interrupted" in out and "[robot2/b] interrupted" in out, out


def test_cli_bad_config(tmp_path, capsys):
    from mrslam_ros.launch import main

    bad = tmp_path / "bad.yaml"
    bad.write_text("nodes: [{module: x}]\n")
    assert main([str(bad)]) == 2
    assert "missing required key nodes[0].name" in capsys.readouterr().err


def test_example_configs_dry_run(capsys):
    """config/launch_*.yaml: the launcher builds every node's command (their params are checked
    against the node configs in test_shipped_yaml.py)."""
    from mrslam_core.configio import load_yaml
    from mrslam_ros.launch import main

    examples = sorted((HERE.parents[1] / "config").glob("launch_*.yaml"))
    assert examples
    for path in examples:
        cfg = load_yaml(LaunchConfig, path)
        assert main([str(path), "--dry-run"]) == 0
        out = capsys.readouterr().out.splitlines()
        assert len(out) == len(cfg.nodes) and all(" -m mrslam_ros." in line for line in out)


def test_view_option_adds_the_view_node_for_the_frontends_robots(capsys):
    from argparse import Namespace

    from mrslam_core.configio import load_yaml
    from mrslam_ros.launch import _robot_namespaces, main, view_spec

    config = HERE.parents[1] / "config" / "launch_sim2.yaml"
    assert main([str(config), "--view", "--view-port", "9001", "--view-ellipsoids", "--dry-run"]) == 0
    view = [line for line in capsys.readouterr().out.splitlines() if "mrslam_ros.view_node" in line]
    assert len(view) == 1 and "__node:=view" in view[0]
    spec = view_spec(Namespace(view_port=9001, view_host=None, view_ellipsoids=True),
                     _robot_namespaces(load_yaml(LaunchConfig, config)))
    assert spec.params == {"robots": ["robot1", "robot2"], "port": 9001, "ellipsoids": True} and not spec.required


def test_params_files_make_mixed_number_lists_floats(tmp_path):
    import yaml

    from mrslam_ros.launch import LaunchConfig, Launcher, NodeSpec

    spec = NodeSpec("mrslam_ros.frontend_node", "frontend", params={"t_base_cam": [0, 0.5, 1], "names": ["a"], "n": 3, "x": None})
    launcher = Launcher(LaunchConfig(nodes=[spec]))
    cmd = launcher.command(spec)
    params = yaml.safe_load(open(cmd[-1]))["/**"]["ros__parameters"]
    assert params == {"t_base_cam": [0.0, 0.5, 1.0], "names": ["a"], "n": 3, "use_sim_time": False}
    assert all(isinstance(v, float) for v in params["t_base_cam"])
    launcher.stop()


def test_demo_nodes_avoid_shared_memory_only_when_a_node_is_killed(tmp_path, monkeypatch):
    """A SIGKILLed Fast DDS participant's restarted process can match and still receive nothing
    over shared memory, so a demo with kill faults runs its nodes on UDPv4 only."""
    import numpy as np

    from mrslam_ros.demo import DemoConfig, Fault, launch_config

    monkeypatch.delenv("FASTDDS_BUILTIN_TRANSPORTS", raising=False)
    facts = {"names": ["robot1", "robot2"], "starts": np.zeros((2, 3)), "t_base_cam": np.eye(4)}
    plain = launch_config(DemoConfig(), facts, tmp_path)
    assert all("FASTDDS_BUILTIN_TRANSPORTS" not in n.env for n in plain.nodes)
    killed = launch_config(DemoConfig(faults=(Fault(at=5.0, node="robot1/frontend", duration=1.0),)), facts, tmp_path)
    assert len(killed.nodes) == 5
    assert all(n.env["FASTDDS_BUILTIN_TRANSPORTS"] == "UDPv4" for n in killed.nodes)
    paused = launch_config(DemoConfig(faults=(Fault(at=5.0, node="robot1/frontend", action="pause", duration=1.0),)),
                           facts, tmp_path)
    assert all("FASTDDS_BUILTIN_TRANSPORTS" not in n.env for n in paused.nodes)
