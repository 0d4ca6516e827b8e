"""The Pioneer 3-DX model: URDF text and the fixed camera extrinsics, both from the config (the
body's footprint from :class:`~mrslam_core.control.platform.PlatformConfig`'s defaults).

Frames: base_link on the floor midway between the wheels (x forward, y left, z up);
camera_link at the middle of the stereo head (x forward); camera_{left,right}_optical_frame at
the optical centres (x right, y down, z forward, REP-103).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mrslam_core.control.platform import PlatformConfig
from mrslam_core.sim.config import DriveConfig, StereoCameraConfig

BASE_URDF = Path(__file__).resolve().parent / "data" / "pioneer3dx.urdf"

# base_link <- optical: optical z (forward) = base x, optical x (right) = −base y, optical y (down) = −base z
R_BASE_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
BODY_TOP = 0.275  # top of the top plate above the floor [m] (see the URDF)
PLATE_INSET = 0.01  # the top plate's edge inside the body's [m]


def camera_extrinsic(camera: StereoCameraConfig, side: str = "left") -> np.ndarray:
    """(4, 4) pose of camera ``side``'s optical frame in base_link (p_base = T · p_optical)."""
    if side not in ("left", "right"):
        raise ValueError(f"side must be left or right, got {side!r}")
    t = np.eye(4)
    t[:3, :3] = R_BASE_OPTICAL
    y = camera.baseline / 2 if side == "left" else -camera.baseline / 2
    t[:3, 3] = [camera.mount_x, y, camera.mount_z]
    return t


def _link(name: str, visual: str = "") -> str:
    inertial = ('<inertial><origin xyz="0 0 0"/><mass value="0.05"/>'
                '<inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-5" iyz="0" izz="1e-5"/></inertial>')
    return f'  <link name="{name}">\n    {inertial}\n{visual}  </link>\n'


def _fixed(parent: str, child: str, xyz: tuple[float, ...], rpy: tuple[float, ...] = (0.0, 0.0, 0.0)) -> str:
    return (f'  <joint name="{child}_joint" type="fixed">\n    <parent link="{parent}"/><child link="{child}"/>\n'
            f'    <origin xyz="{xyz[0]:.6g} {xyz[1]:.6g} {xyz[2]:.6g}" rpy="{rpy[0]:.9g} {rpy[1]:.9g} {rpy[2]:.9g}"/>\n'
            f'  </joint>\n')


def _visual(geometry: str, material: str, xyz: tuple[float, ...] = (0, 0, 0), rpy: tuple[float, ...] = (0, 0, 0)) -> str:
    return (f'    <visual>\n      <origin xyz="{xyz[0]:.6g} {xyz[1]:.6g} {xyz[2]:.6g}" rpy="{rpy[0]:.9g} {rpy[1]:.9g} '
            f'{rpy[2]:.9g}"/>\n      <geometry>{geometry}</geometry>\n      <material name="{material}"/>\n    </visual>\n')


def carrier_mesh(half: float) -> str:
    """Wavefront OBJ text of a tag carrier: the four sides of a cube of half-width ``half`` [m]
    centred at the origin, each face textured with the whole image, upright and unmirrored as
    seen from outside (the top and bottom are open)."""
    lines, faces = [], []
    # outward normal and the direction that is "right" for a viewer looking at that face
    for k, (n, r) in enumerate((((1, 0), (0, 1)), ((0, 1), (-1, 0)), ((-1, 0), (0, -1)), ((0, -1), (1, 0)))):
        for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
            lines.append(f"v {half * (n[0] + a * r[0]):.6g} {half * (n[1] + a * r[1]):.6g} {half * b:.6g}")
        faces += [f"f {4 * k + 1}/1 {4 * k + 2}/2 {4 * k + 3}/3", f"f {4 * k + 1}/1 {4 * k + 3}/3 {4 * k + 4}/4"]
    return "\n".join(lines + ["vt 0 0", "vt 1 0", "vt 1 1", "vt 0 1"] + faces) + "\n"


def robot_description(camera: StereoCameraConfig, drive: DriveConfig, body: PlatformConfig | None = None,
                      carrier: tuple[str, float, float] | None = None) -> str:
    """URDF of the robot with the footprint of ``body`` (default: ``PlatformConfig()``, the
    simulated Pioneer), wheels at ±track/2 and the stereo head where ``camera`` puts it.

    The wheels are fixed links (the simulator drives the base kinematically); the optical frames
    match :func:`camera_extrinsic`. ``carrier`` = (mesh file of :func:`carrier_mesh`, its
    half-width [m], the height of its centre [m]) adds a ``tag_carrier`` link above base_link
    (its texture, the robot's tag, is set on the loaded body).
    """
    parts = []
    r, half = drive.wheel_radius, drive.track / 2
    for side, y in (("left", half), ("right", -half)):
        wheel = _visual(f'<cylinder radius="{r:.6g}" length="0.047"/>', "black", rpy=(np.pi / 2, 0, 0))
        parts += [_link(f"{side}_wheel", wheel), _fixed("base_link", f"{side}_wheel", (0.0, y, r))]
    head_x = camera.mount_x - 0.03
    mast_len = camera.mount_z - 0.02 - BODY_TOP
    mast = _visual(f'<cylinder radius="0.015" length="{mast_len:.6g}"/>', "grey", xyz=(head_x, 0, BODY_TOP + mast_len / 2))
    head = _visual(f'<box size="0.05 {camera.baseline + 0.06:.6g} 0.04"/>', "grey", xyz=(-0.03, 0, 0))
    parts += [_link("camera_mast", mast), _fixed("base_link", "camera_mast", (0.0, 0.0, 0.0)),
              _link("camera_link", head), _fixed("base_link", "camera_link", (camera.mount_x, 0.0, camera.mount_z))]
    for side, y in (("left", camera.baseline / 2), ("right", -camera.baseline / 2)):
        parts += [_link(f"camera_{side}_optical_frame"),
                  _fixed("camera_link", f"camera_{side}_optical_frame", (0.0, y, 0.0), (-np.pi / 2, 0.0, -np.pi / 2))]
    if carrier is not None:
        mesh, half, height = carrier
        if height - half <= camera.mount_z + 0.02:
            raise ValueError("the tag carrier must be above the stereo head")
        # TinyRenderer does not return from a frame whose eye lies in the plane of a face
        if min(abs(camera.mount_x - half), abs(camera.mount_x + half), abs(camera.baseline / 2 - half)) < 0.01:
            raise ValueError("a face of the tag carrier would lie in the plane of a camera")
        parts += [_link("tag_carrier", _visual(f'<mesh filename="{mesh}"/>', "white")),
                  _fixed("base_link", "tag_carrier", (0.0, 0.0, height))]
    body = body or PlatformConfig()
    fill = {"centre_x": body.centre_x, "length": body.length, "width": body.width,
            "plate_length": body.length - 2 * PLATE_INSET, "plate_width": body.width - 2 * PLATE_INSET}
    base = BASE_URDF.read_text()
    for key, value in fill.items():
        base = base.replace("{" + key + "}", f"{value:.6g}")
    end = base.rindex("</robot>")
    return base[:end] + "".join(parts) + base[end:]
