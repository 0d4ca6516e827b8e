"""The Foxglove layout of the live view (config/foxglove_layout.json), built with the SDK's
:mod:`foxglove.layouts`.

A 3D panel in the ``map`` frame (wide, on the left) shows the occupancy grid, the landmarks, the
particles, the TF tree, the frontiers and, for each robot, its estimated pose and path, its
ground-truth pose and path, its goal and its plan; the landmark ellipsoids are listed but hidden
(they are streamed only on request, ``-p ellipsoids:=true``). One Image panel per robot (stacked
on the right) shows its left camera with the points it observed drawn on it. Every topic named
is a channel of :func:`mrslam_ros.foxglove_view.channel_names`.

Colours: each robot has its own (:data:`COLORS`, in the order of ``robots``): its pose and path
solid, its goal and plan translucent; ground truth is grey and thinner. The grid is drawn from the
RGBA fields :func:`mrslam_ros.foxglove_view.occupancy_grid` writes beside the int8 ``occupancy``:
white free to black occupied, unknown cells a faint translucent grey.

The Image panels draw the raw (unrectified) image: the points on ``/<robot>/image_points`` are
pixels of the raw image (:func:`mrslam_ros.foxglove_view.project_points` applies the lens
distortion). They are not synchronised with the image by timestamp: a synchronised panel shows
nothing while the points are missing (no camera mount on /tf_static), so the points of a frame
may be drawn on the next one.

``python -m mrslam_ros.view_layout --write`` rewrites config/foxglove_layout.json;
``test/ros/test_view_layout.py`` fails when the file and this module differ. Without ``--write``
the layout is printed (``--robots`` for another team).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

import foxglove.layouts as fl

#: the checked-in layout file
LAYOUT_FILE = Path(__file__).resolve().parents[1] / "config" / "foxglove_layout.json"

#: the demo's team
ROBOTS = ("robot1", "robot2", "robot3")

#: each robot's colour, in the order of ``robots`` (cycled for larger teams)
COLORS = ("#e53935", "#43a047", "#1e88e5", "#fb8c00", "#8e24aa", "#00acc1")

#: ground truth (pose and path), every robot
TRUTH_COLOR = "#9e9e9e"

#: the frame every pose, path, landmark and the grid are in
MAP_FRAME = "map"


def _robot_topics(robot: str, color: str) -> dict[str, object]:
    """The 3D panel's settings of one robot's channels."""
    ns = f"/{robot}"
    return {
        f"{ns}/pose": fl.BaseRendererPoseTopicSettings(visible=True, type="arrow", arrow_scale=(0.5, 0.12, 0.12),
                                                       color=color),
        f"{ns}/path": fl.BaseRendererPosesTopicSettings(visible=True, type="line", line_width=0.04,
                                                        gradient=(color, color)),
        f"{ns}/ground_truth": fl.BaseRendererPoseTopicSettings(visible=True, type="arrow",
                                                               arrow_scale=(0.4, 0.08, 0.08), color=TRUTH_COLOR),
        f"{ns}/ground_truth_path": fl.BaseRendererPosesTopicSettings(visible=True, type="line", line_width=0.02,
                                                                     gradient=(TRUTH_COLOR, TRUTH_COLOR)),
        f"{ns}/goal": fl.BaseRendererPoseTopicSettings(visible=True, type="arrow", arrow_scale=(0.6, 0.25, 0.25),
                                                       color=color + "99"),
        f"{ns}/plan": fl.BaseRendererPosesTopicSettings(visible=True, type="line", line_width=0.025,
                                                        gradient=(color + "99", color + "99")),
    }


def map_panel(robots: Sequence[str] = ROBOTS) -> fl.ThreeDeePanel:
    """The 3D panel: the team's map, estimates and plans in the map frame."""
    topics: dict[str, object] = {
        "/map": fl.BaseRendererGridTopicSettings(visible=True, color_mode="rgba-fields", draw_behind=True),
        "/slam/landmarks": fl.BaseRendererPointCloudTopicSettings(visible=True, point_size=4.0, point_shape="circle",
                                                                  color_mode="flat", flat_color="#6a1b9aff"),
        "/slam/landmark_ellipsoids": fl.BaseRendererSceneUpdateTopicSettings(visible=False),
        "/slam/particles": fl.BaseRendererPosesTopicSettings(visible=True, type="arrow",
                                                             arrow_scale=(0.15, 0.02, 0.02),
                                                             gradient=("#5d4037b3", "#5d4037b3")),
        "/exploration/frontiers": fl.BaseRendererSceneUpdateTopicSettings(visible=True),
        "/tf": fl.BaseRendererBaseSettings(visible=True),
    }
    for i, robot in enumerate(robots):
        topics.update(_robot_topics(robot, COLORS[i % len(COLORS)]))
    config = fl.ThreeDeeConfig(
        follow_tf=MAP_FRAME,
        fixed_frame=MAP_FRAME,
        follow_mode="follow-none",
        # above the middle of the demo's office (20 m x 12 m from the map origin), tilted
        camera_state=fl.ThreeDeeCameraState(distance=24.0, perspective=True, phi=30.0, target=(0.0, 0.0, 0.0),
                                            target_offset=(10.0, 6.0, 0.0), target_orientation=(0.0, 0.0, 0.0, 1.0),
                                            theta_offset=0.0, fovy=45.0, near=0.5, far=5000.0),
        scene=fl.BaseRendererSceneSettings(
            transforms=fl.BaseRendererTransforms(show_label=True, label_size=0.15, axis_size=0.3)),
        layers={"grid": fl.BaseRendererGridLayerSettings(instance_id="grid", label="Grid", frame_id=MAP_FRAME,
                                                         size=40.0, divisions=40.0, line_width=1.0,
                                                         color="#a0a0a480", position=(0.0, 0.0, -0.01))},
        topics=topics,
    )
    return fl.ThreeDeePanel(title="Team map", config=config)


def camera_panel(robot: str) -> fl.ImagePanel:
    """``robot``'s left camera image with the points it observed in it."""
    mode = fl.ImageModeConfig(image_topic=f"/{robot}/image", image_schema_name="foxglove.RawImage",
                              calibration_topic=f"/{robot}/camera_calibration",
                              annotations={f"/{robot}/image_points": fl.ImageAnnotationSettings(visible=True)},
                              rectify_image=False)
    return fl.ImagePanel(title=f"{robot} left camera", config=fl.ImageConfig(image_mode=mode))


def layout(robots: Sequence[str] = ROBOTS) -> fl.Layout:
    """The view's layout for the team ``robots``: the 3D panel (3/4 of the width) beside a column
    of one Image panel per robot."""
    robots = tuple(robots)
    if not robots:
        return fl.Layout(content=map_panel(robots))
    cameras = fl.SplitContainer(direction="column",
                                items=[fl.SplitItem(proportion=1, content=camera_panel(r)) for r in robots])
    return fl.Layout(content=fl.SplitContainer(direction="row", items=[
        fl.SplitItem(proportion=3, content=map_panel(robots)),
        fl.SplitItem(proportion=1, content=cameras),
    ]))


def render(robots: Sequence[str] = ROBOTS) -> str:
    """The layout as the file holds it: the SDK's JSON, indented by 2, keys sorted, a final newline."""
    return json.dumps(json.loads(layout(robots).to_json()), indent=2, sort_keys=True) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m mrslam_ros.view_layout",
                                 description="Print the Foxglove layout of the live view, or rewrite "
                                             f"{LAYOUT_FILE.relative_to(LAYOUT_FILE.parents[1])}.")
    ap.add_argument("--write", action="store_true", help=f"rewrite {LAYOUT_FILE} (the demo's team)")
    ap.add_argument("--robots", nargs="+", metavar="NAME",
                    help=f"print the layout of this team (default: {' '.join(ROBOTS)})")
    args = ap.parse_args(argv)
    if args.write and args.robots:
        ap.error("--write writes the checked-in layout of the demo's team; print other teams' with --robots alone")
    text = render(args.robots or ROBOTS)
    if args.write:
        LAYOUT_FILE.write_text(text)
        print(f"wrote {LAYOUT_FILE}")
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
