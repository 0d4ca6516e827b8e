"""World files, the occupancy raster and the robot description."""

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from mrslam_core.sim import DriveConfig, SimError, StereoCameraConfig, load_world
from mrslam_core.sim.robot import camera_extrinsic, robot_description
from mrslam_core.sim.world import BUILTIN
from mrslam_core.sim.scene import box_mesh


def test_builtin_worlds():
    office = load_world("office")
    assert office.size == (20.0, 12.0) and len(office.start_poses) >= 3
    assert "repetitive" in office.wall_textures and "unique" in office.wall_textures
    occ = office.occupancy(0.1)
    assert occ.shape == (120, 200)
    assert not occ[60, 10] and occ[50, 10]  # corridor (y = 6.05) free, the wall at y = 5 occupied
    reach = office.reachable_free(0.1)
    assert not (reach & occ).any()
    # every room is reachable through a door: nearly all free cells count
    assert 0.9 < reach.sum() / (~occ).sum() <= 1.0
    small = load_world("small")
    assert small.occupancy(0.5).shape == (8, 12)


def test_reachable_free_excludes_a_closed_room(tmp_path):
    path = tmp_path / "w.yaml"
    path.write_text("size: [4, 2]\nwall_thickness: 0.1\n"
                    "walls: [[0, 0, 4, 0], [4, 0, 4, 2], [4, 2, 0, 2], [0, 2, 0, 0], [2, 0, 2, 2]]\n"
                    "start_poses: [[1, 1, 0]]\n")
    world = load_world(path)
    reach = world.reachable_free(0.05)
    free = ~world.occupancy(0.05)
    assert reach[:, :38].sum() >= 0.99 * free[:, :38].sum()  # the start's room, all but its corners
    assert reach[:, 42:].sum() == 0  # the closed room east of x = 2.05


def test_mapping_form_and_textures(tmp_path):
    path = tmp_path / "w.yaml"
    path.write_text(
        "size: [4, 4]\n"
        "walls:\n  - [0, 0, 4, 0]\n  - {from: [0, 2], to: [2, 2], thickness: 0.3, height: 1.0, texture: plain}\n"
        "boxes:\n  - {centre: [3, 3], size: [0.5, 0.4, 0.7], yaw_deg: 90, texture: repetitive}\n"
        "start_poses: [[1, 1, 0]]\n")
    world = load_world(path)
    assert world.wall_textures == ("unique", "plain") and world.box_textures == ("repetitive",)
    np.testing.assert_allclose(world.wall_thicknesses, [0.15, 0.3])
    np.testing.assert_allclose(world.boxes[0], [3, 3, 0.5, 0.4, 0.7, np.pi / 2])
    occ = world.occupancy(0.05)
    assert occ[int(2.1 / 0.05), int(1.0 / 0.05)] and not occ[int(2.2 / 0.05), int(1.0 / 0.05)]  # ±0.15 m


@pytest.mark.parametrize("text, message", [
    ("size: [4, 4]\nwalls: [[0, 0, 4]]\nstart_poses: [[1, 1, 0]]\n", r"walls must be a list of 4-number rows"),
    ("size: [4, 4]\nwals: []\n", "unknown key wals"),
    ("size: [4, 4]\nwalls: [[0, 0, 4, 0]]\n", "missing key start_poses"),
    ("size: [4, 4]\nwalls: [{from: [0, 0], to: [1, 0], texture: marble}]\nstart_poses: [[1, 1, 0]]\n", "texture must be"),
    ("size: [4, 4]\nwalls: [[0, 0, 4, 0]]\nstart_poses: [[9, 1, 0]]\n", "outside the world"),
    ("size: [4, 4]\nwalls: [[0, 0, 4, 0]]\nrepetitive: [3]\nstart_poses: [[1, 1, 0]]\n", "repetitive names"),
    ("size: [4\n", "cannot read it as YAML"),
])
def test_bad_world_files(tmp_path, text, message):
    path = tmp_path / "w.yaml"
    path.write_text(text)
    with pytest.raises(SimError, match=message):
        load_world(path)


_OUTER = [[0, 0, 8, 0], [8, 0, 8, 4], [8, 4, 0, 4], [0, 4, 0, 0]]


@pytest.mark.parametrize("walls, boxes, starts, message", [
    # walls along each other, a wall crossing another's interior
    ([[1, 2, 5, 2], [4, 2, 7, 2]], [], [[1, 1, 0]], r"walls\[5\] overlaps walls\[4\] along 1.00 m"),
    ([[1, 2, 5, 2], [3, 1, 3, 3]], [], [[1, 1, 0]], r"walls\[5\] crosses walls\[4\] at \(3.00, 2.00\)"),
    ([[2, 0, 2, 4.5]], [], [[1, 1, 0]], r"walls\[4\] crosses walls\[2\]"),  # through the outer wall
    # a start pose in a wall (nearer than the robot's half width), in a box, shut off from the first
    ([], [], [[1, 1, 0], [3, 0.2, 0]], r"start_poses\[1\] \(3, 0.2\) is inside walls\[0\]"),
    ([], [[5, 2, 1, 1, 1, 0]], [[1, 1, 0], [5.6, 2, 0]], r"start_poses\[1\] \(5.6, 2\) is inside boxes\[0\]"),
    ([[4, 0, 4, 4]], [], [[1, 1, 0], [6, 2, 0]], r"start_poses\[1\] \(6, 2\) cannot be reached from start_poses\[0\]"),
    ([[4, 0, 4, 1.5], [4, 2.1, 4, 4]], [], [[1, 1, 0], [6, 2, 0]], r"start_poses\[1\] .* cannot be reached"),  # 0.5 m door
])
def test_impossible_worlds_name_the_field(tmp_path, walls, boxes, starts, message):
    path = tmp_path / "w.yaml"
    path.write_text(f"size: [8, 4]\nwall_thickness: 0.1\nwalls: {_OUTER + walls}\nboxes: {boxes}\nstart_poses: {starts}\n")
    with pytest.raises(SimError, match=message) as err:
        load_world(path)
    assert str(path) in str(err.value)


def test_corners_junctions_and_doors_pass():
    world = load_world({"size": [8, 4], "wall_thickness": 0.1, "start_poses": [[1, 1, 0], [6, 2, 0]],
                        "walls": [[0, 0, 4, 0], [4, 0, 8, 0], [8, 0, 8, 4], [8, 4, 0, 4], [0, 4, 0, 0],  # end to end, L
                                  [4, 0, 4, 1.5], [4, 2.5, 4, 4],  # T junctions, a 1 m door
                                  [6, 4, 6, 3.05]]})  # a stub ending at the wall's face
    assert world.name == "<mapping>" and len(world.walls) == 8


@pytest.mark.parametrize("name", sorted(p.stem for p in BUILTIN.glob("*.yaml")))
def test_every_builtin_world_is_valid_and_connected(name):
    world = load_world(name)
    occ = world.occupancy(0.1)
    assert world.reachable_free(0.1).sum() >= 0.95 * (~occ).sum()


def test_unknown_world_name():
    with pytest.raises(SimError, match="no world 'castle'"):
        load_world("castle")


def test_box_mesh_uvs_keep_the_density():
    verts, normals, uvs, idx, (rows, cols) = box_mesh(0.75, 0.075, 1.25, 100.0)
    assert (rows, cols) == (265, 330)  # (2.5 + 0.15) m and the 3.3 m perimeter at 100 texels/m
    # a metre along any edge is 100 texels: compare a side face's edge lengths in metres and texels
    tri = verts[idx].reshape(-1, 3, 3)
    tex = (uvs[idx] * [cols, rows]).reshape(-1, 3, 2)
    for k in (0, 2, 6):
        np.testing.assert_allclose(np.linalg.norm(np.diff(tex[k], axis=0), axis=1),
                                   100 * np.linalg.norm(np.diff(tri[k], axis=0), axis=1), rtol=0.02)
    # counter-clockwise seen from outside: the triangle normal points along the vertex normal
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.all(np.einsum("ij,ij->i", n, normals[idx[::3]]) > 0)


def test_robot_description_matches_the_extrinsics():
    cam = StereoCameraConfig(baseline=0.2, mount_z=0.5)
    root = ET.fromstring(robot_description(cam, DriveConfig()))
    joints = {j.find("child").get("link"): j for j in root.iter("joint")}
    head = np.array(joints["camera_link"].find("origin").get("xyz").split(), float)
    for side in ("left", "right"):
        origin = joints[f"camera_{side}_optical_frame"].find("origin")
        xyz = head + np.array(origin.get("xyz").split(), float)
        roll, pitch, yaw = np.array(origin.get("rpy").split(), float)
        cr, sr, cy, sy = np.cos(roll), np.sin(roll), np.cos(yaw), np.sin(yaw)
        rot = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]]) @ np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
        assert pitch == 0
        ext = camera_extrinsic(cam, side)
        np.testing.assert_allclose(xyz, ext[:3, 3], atol=1e-6)
        np.testing.assert_allclose(rot, ext[:3, :3], atol=1e-6)
    assert ext[1, 3] == pytest.approx(-0.1)
    wheels = {s: float(joints[f"{s}_wheel"].find("origin").get("xyz").split()[1]) for s in ("left", "right")}
    assert wheels == {"left": pytest.approx(0.165), "right": pytest.approx(-0.165)}
