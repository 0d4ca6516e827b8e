"""The viewer configs in config/: the Foxglove layout is the generator's output and names only the
view's channels; the RViz config names only topics the nodes publish, with RViz's own classes."""

import json
from pathlib import Path

import pytest
import yaml

pytest.importorskip("foxglove", reason="foxglove-sdk (the `view` extra) is not installed")

import foxglove.layouts as fl  # noqa: E402

from mrslam_ros import foxglove_view as fv  # noqa: E402
from mrslam_ros import view_layout as vl  # noqa: E402

CONFIG = Path(__file__).resolve().parents[2] / "config"
TEAM = ("robot1", "robot2", "robot3")

#: what the nodes publish, per robot (simulator, frontend, central SLAM node, exploration node)
ROBOT_TOPICS = ("stereo/left/image_raw", "stereo/right/image_raw", "stereo/left/camera_info",
                "stereo/right/camera_info", "odom", "ground_truth", "observations", "scan", "visual_odom",
                "pose", "path", "goal", "plan", "cmd_vel")
#: ... and once for the team
TEAM_TOPICS = ("/tf", "/tf_static", "/clock", "/map", "/slam/landmarks", "/slam/landmark_markers",
               "/slam/particles", "/exploration/frontiers", "/diagnostics")
PUBLISHED = {f"/{r}/{t}" for r in TEAM for t in ROBOT_TOPICS} | set(TEAM_TOPICS)


def _layout_topics(node, out: set[str]) -> set[str]:
    """Every topic a layout's JSON names: the keys of ``topics``, ``annotations`` and
    ``syncedTopics`` maps, and the value of every ``...Topic`` key."""
    if isinstance(node, dict):
        for key, value in node.items():
            if key in ("topics", "annotations", "syncedTopics") and isinstance(value, dict):
                out.update(value)
            elif key.endswith("Topic") and isinstance(value, str):
                out.add(value)
            _layout_topics(value, out)
    elif isinstance(node, list):
        for value in node:
            _layout_topics(value, out)
    return out


def _panels(node) -> list[dict]:
    """The panels of a layout's JSON, depth first."""
    if isinstance(node, dict):
        if node.get("type") == "panel":
            return [node]
        return [p for value in node.values() for p in _panels(value)]
    if isinstance(node, list):
        return [p for value in node for p in _panels(value)]
    return []


def _displays(displays: list[dict]) -> list[dict]:
    """An RViz display list with the displays of its groups, flattened."""
    out = []
    for d in displays:
        out.append(d)
        out.extend(_displays(d.get("Displays", [])))
    return out


@pytest.fixture(scope="module")
def layout_json() -> dict:
    return json.loads((CONFIG / "foxglove_layout.json").read_text())


@pytest.fixture(scope="module")
def rviz() -> dict:
    return yaml.safe_load((CONFIG / "mrslam.rviz").read_text())


# ----------------------------------------------------------------------------- Foxglove layout
def test_layout_file_is_the_generators_output():
    text = (CONFIG / "foxglove_layout.json").read_text()
    assert text == vl.render(TEAM), (
        "config/foxglove_layout.json differs from mrslam_ros/view_layout.py: "
        "run `python -m mrslam_ros.view_layout --write`")


def test_layout_file_is_the_sdks_serialization(layout_json):
    sdk = json.loads(vl.layout(TEAM).to_json())
    assert layout_json == sdk
    # the top level is what the SDK's Layout writes (a bare layout has the same keys)
    bare = json.loads(fl.Layout(content=fl.ThreeDeePanel()).to_json())
    assert set(layout_json) == set(bare) == {"version", "content"}


def test_layout_names_only_the_views_channels_and_all_of_them(layout_json):
    channels = set(fv.channel_names(TEAM, ellipsoids=True))
    named = _layout_topics(layout_json, set())
    assert named <= channels, f"not channels of the view: {sorted(named - channels)}"
    assert named == channels, f"channels missing from the layout: {sorted(channels - named)}"


def test_layout_panels(layout_json):
    panels = _panels(layout_json["content"])
    assert [p["panelType"] for p in panels] == ["ThreeDee", "Image", "Image", "Image"]
    three = panels[0]["config"]
    assert three["followTf"] == three["fixedFrame"] == "map"
    topics = three["topics"]
    assert topics["/slam/landmark_ellipsoids"]["visible"] is False
    assert all(s["visible"] for t, s in topics.items() if t != "/slam/landmark_ellipsoids")
    assert topics["/map"]["colorMode"] == "rgba-fields"
    # each robot's estimate and path in its own colour, ground truth in another
    colors = {topics[f"/{r}/pose"]["color"] for r in TEAM}
    assert len(colors) == 3 and topics["/robot1/ground_truth_path"]["gradient"][0] not in colors
    for robot, panel in zip(TEAM, panels[1:]):
        mode = panel["config"]["imageMode"]
        assert mode["imageTopic"] == f"/{robot}/image"
        assert mode["calibrationTopic"] == f"/{robot}/camera_calibration"
        assert mode["annotations"] == {f"/{robot}/image_points": {"visible": True}}


def test_layout_of_another_team():
    named = _layout_topics(json.loads(vl.render(("alpha", "beta"))), set())
    assert named == set(fv.channel_names(("alpha", "beta"), ellipsoids=True))
    assert [p["panelType"] for p in _panels(json.loads(vl.layout(()).to_json())["content"])] == ["ThreeDee"]


def test_layout_cli(capsys, monkeypatch, tmp_path):
    assert vl.main([]) == 0
    assert capsys.readouterr().out == vl.render(TEAM)
    assert vl.main(["--robots", "a"]) == 0
    assert "/a/image" in capsys.readouterr().out
    target = tmp_path / "layout.json"
    monkeypatch.setattr(vl, "LAYOUT_FILE", target)
    assert vl.main(["--write"]) == 0
    assert target.read_text() == vl.render(TEAM)
    with pytest.raises(SystemExit):
        vl.main(["--write", "--robots", "a"])


# ----------------------------------------------------------------------------- RViz config
def test_rviz_config_names_published_topics_with_rviz_classes(rviz):
    manager = rviz["Visualization Manager"]
    assert manager["Global Options"]["Fixed Frame"] == "map"
    displays = _displays(manager["Displays"])
    topics = [d["Topic"]["Value"] for d in displays if "Topic" in d]
    assert set(topics) <= PUBLISHED, f"not published by the nodes: {sorted(set(topics) - PUBLISHED)}"
    classes = ([d["Class"] for d in displays] + [p["Class"] for p in rviz["Panels"]]
               + [t["Class"] for t in manager["Tools"]] + [manager["Views"]["Current"]["Class"]])
    bad = [c for c in classes if not c.startswith(("rviz_default_plugins/", "rviz_common/"))]
    assert not bad, f"not RViz classes: {bad}"


def test_rviz_config_displays(rviz):
    displays = _displays(rviz["Visualization Manager"]["Displays"])
    by_topic = {d["Topic"]["Value"]: d for d in displays if "Topic" in d}
    expected = {"/map": "Map", "/slam/landmarks": "PointCloud2", "/slam/landmark_markers": "MarkerArray",
                "/slam/particles": "PoseArray", "/exploration/frontiers": "MarkerArray"}
    for r in TEAM:
        expected.update({f"/{r}/path": "Path", f"/{r}/ground_truth": "Odometry",
                         f"/{r}/pose": "PoseWithCovariance", f"/{r}/goal": "Pose", f"/{r}/plan": "Path",
                         f"/{r}/stereo/left/image_raw": "Image"})
    classes = {t: d["Class"] for t, d in by_topic.items()}
    assert classes == {t: f"rviz_default_plugins/{c}" for t, c in expected.items()}
    assert {d["Class"] for d in displays} >= {"rviz_default_plugins/Grid", "rviz_default_plugins/TF"}
    # /map is published volatile: a transient-local subscription would not match it
    assert by_topic["/map"]["Topic"]["Durability Policy"] == "Volatile"
    # ellipsoids only on request (the central node builds them only while subscribed)
    assert by_topic["/slam/landmark_markers"]["Enabled"] is False
    assert all(d["Enabled"] for t, d in by_topic.items() if t != "/slam/landmark_markers")
    assert rviz["Visualization Manager"]["Views"]["Current"]["Class"] == "rviz_default_plugins/TopDownOrtho"
