"""The simulated team: pybullet physics, differential drive, wheel odometry, stereo rendering.

Frames (REP-103/105): map (x, y on the floor, z up); each robot's base_link on the floor between
the wheels (x forward, y left); the left camera's optical frame (x right, y down, z forward).
Time is simulated: the clock advances one physics step at a time (ns).
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet as p

from mrslam_core.frontend.camera import CameraCalibration
from mrslam_core.geometry.se2 import compose, wrap_angle
from mrslam_core.sim.config import SimConfig
from mrslam_core.sim.errors import SimError
from mrslam_core.sim.textures import repetitive_texture, unique_texture, write_texture
from mrslam_core.sim.world import World, load_world

URDF = Path(__file__).resolve().parent / "data" / "pioneer3dx.urdf"
R_BASE_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


@dataclass
class _Robot:
    body: int
    cmd: np.ndarray  # commanded (v, ω)
    vel: np.ndarray  # actual (v, ω) after acceleration limits
    odom: np.ndarray  # odom-frame pose (x, y, θ)
    odom_twist: np.ndarray  # (v, ω) measured by the wheels
    prev_truth: np.ndarray
    next_frame_ns: int


@dataclass(frozen=True)
class StereoFrame:
    """One rendered stereo pair.

    Attributes:
        left, right: (H, W) uint8 grey images (mono8), rows top to bottom.
        depth: (H, W) float32 z-depth of the left image in its optical frame [m].
        stamp_ns: simulated time of the exposure [ns].
    """

    left: np.ndarray
    right: np.ndarray
    depth: np.ndarray
    stamp_ns: int


class Simulation:
    """A pybullet world with Pioneer 3-DX robots (DIRECT mode, one client per instance).

    Args:
        config: simulation parameters.
        world: a parsed world; default ``load_world(config.world)``.
    """

    def __init__(self, config: SimConfig | None = None, world: World | None = None):
        self.config = config or SimConfig()
        self.world = world or load_world(self.config.world)
        self.rng = np.random.default_rng(self.config.seed)
        self.client = p.connect(p.DIRECT)
        p.setGravity(0, 0, 0, physicsClientId=self.client)
        p.setTimeStep(1.0 / self.config.physics_hz, physicsClientId=self.client)
        self._dt_ns = int(round(1e9 / self.config.physics_hz))
        self.time_ns = 0
        self.robots: dict[str, _Robot] = {}
        self._texdir = Path(tempfile.gettempdir()) / f"mrslam_textures_{self.config.texture_size}"
        self._build_world()
        cam = self.config.camera
        self._fx = cam.width / (2.0 * np.tan(np.radians(cam.hfov_deg) / 2))
        self._vfov_deg = float(np.degrees(2 * np.arctan(np.tan(np.radians(cam.hfov_deg) / 2) * cam.height / cam.width)))
        self._proj = p.computeProjectionMatrixFOV(self._vfov_deg, cam.width / cam.height, cam.near, cam.far)

    # ------------------------------------------------------------------ world
    def _texture(self, name: str, img: np.ndarray) -> int:
        path = write_texture(img, self._texdir, name)
        return p.loadTexture(str(path), physicsClientId=self.client)

    def _build_world(self) -> None:
        w, cid, size = self.world, self.client, self.config.texture_size
        seed = self.config.seed
        tile = 2.0
        nx, ny = int(np.ceil(w.size[0] / tile)), int(np.ceil(w.size[1] / tile))
        floor_vis = p.createVisualShape(p.GEOM_BOX, halfExtents=[tile / 2, tile / 2, 0.005], physicsClientId=cid)
        for i in range(nx):
            for j in range(ny):
                floor = p.createMultiBody(0, -1, floor_vis, [(i + 0.5) * tile, (j + 0.5) * tile, -0.005],
                                          physicsClientId=cid)
                tex = self._texture(f"floor_{seed}_{i}_{j}", unique_texture(size, seed * 100003 + 50000 + i * 97 + j))
                p.changeVisualShape(floor, -1, textureUniqueId=tex, rgbaColor=[1, 1, 1, 1], physicsClientId=cid)
        rep = self._texture("repetitive", repetitive_texture(size))
        for k, (centre, half, yaw, height, idx) in enumerate(w.visual_pieces()):
            # one body per piece with its own collision box (a body without a visual shape would be
            # drawn from its collision shape and z-fight with the textured faces)
            ext = [half[0], half[1], height / 2]
            col = p.createCollisionShape(p.GEOM_BOX, halfExtents=ext, physicsClientId=cid)
            vis = p.createVisualShape(p.GEOM_BOX, halfExtents=ext, physicsClientId=cid)
            body = p.createMultiBody(0, col, vis, [centre[0], centre[1], height / 2],
                                     p.getQuaternionFromEuler([0, 0, yaw]), physicsClientId=cid)
            tex = rep if idx in w.repetitive else self._texture(f"solid_{seed}_{k}", unique_texture(size, seed * 100003 + k))
            p.changeVisualShape(body, -1, textureUniqueId=tex, rgbaColor=[1, 1, 1, 1], physicsClientId=cid)

    # ------------------------------------------------------------------ robots
    def add_robot(self, name: str, start_pose: np.ndarray | None = None) -> None:
        """Place a robot at ``start_pose`` (x, y, θ) in the map (default: the world's next start)."""
        if name in self.robots:
            raise SimError(f"robot {name!r} exists already")
        if start_pose is None:
            if len(self.robots) >= len(self.world.start_poses):
                raise SimError(f"world {self.world.name} has only {len(self.world.start_poses)} start poses")
            start_pose = self.world.start_poses[len(self.robots)]
        start = np.asarray(start_pose, dtype=float)
        if start.shape != (3,) or not np.isfinite(start).all():
            raise SimError(f"start pose must be 3 finite numbers, got {start_pose!r}")
        body = p.loadURDF(str(URDF), [start[0], start[1], 0.0], p.getQuaternionFromEuler([0, 0, start[2]]),
                          physicsClientId=self.client)
        p.changeDynamics(body, -1, linearDamping=0, angularDamping=0, physicsClientId=self.client)
        self.robots[name] = _Robot(body, np.zeros(2), np.zeros(2), np.zeros(3), np.zeros(2), start.copy(),
                                   self.time_ns)

    def _robot(self, name: str) -> _Robot:
        try:
            return self.robots[name]
        except KeyError:
            raise SimError(f"unknown robot {name!r}; have {sorted(self.robots)}") from None

    def set_command(self, name: str, v: float, w: float) -> None:
        """Command forward speed v [m/s] and turn rate ω [rad/s] (clipped to the drive limits)."""
        if not (np.isfinite(v) and np.isfinite(w)):
            raise SimError(f"{name}: non-finite command ({v}, {w})")
        d = self.config.drive
        self._robot(name).cmd = np.array([np.clip(v, -d.max_speed, d.max_speed),
                                          np.clip(w, -d.max_turn_rate, d.max_turn_rate)])

    def ground_truth(self, name: str) -> np.ndarray:
        """Pose (x, y, θ) of base_link in the map [m, m, rad]."""
        pos, orn = p.getBasePositionAndOrientation(self._robot(name).body, physicsClientId=self.client)
        return np.array([pos[0], pos[1], p.getEulerFromQuaternion(orn)[2]])

    def odometry(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """Wheel odometry: (pose (x, y, θ) of base_link in the robot's odom frame, twist (v, ω))."""
        r = self._robot(name)
        return r.odom.copy(), r.odom_twist.copy()

    # ------------------------------------------------------------------ time
    def step(self) -> None:
        """Advance one physics step: acceleration limits, drive, contacts, odometry."""
        dt = 1.0 / self.config.physics_hz
        d = self.config.drive
        for r in self.robots.values():
            dv = np.clip(r.cmd - r.vel, [-d.max_accel * dt, -d.max_turn_accel * dt], [d.max_accel * dt, d.max_turn_accel * dt])
            r.vel = r.vel + dv
            th = r.prev_truth[2]
            p.resetBaseVelocity(r.body, [r.vel[0] * np.cos(th), r.vel[0] * np.sin(th), 0], [0, 0, r.vel[1]],
                                physicsClientId=self.client)
        p.stepSimulation(physicsClientId=self.client)
        self.time_ns += self._dt_ns
        for name, r in self.robots.items():
            pos, orn = p.getBasePositionAndOrientation(r.body, physicsClientId=self.client)
            yaw = p.getEulerFromQuaternion(orn)[2]
            # keep the robot on the floor and upright (contacts may tilt it)
            p.resetBasePositionAndOrientation(r.body, [pos[0], pos[1], 0.0], p.getQuaternionFromEuler([0, 0, yaw]),
                                              physicsClientId=self.client)
            truth = np.array([pos[0], pos[1], yaw])
            self._integrate_odometry(r, truth, dt)
            r.prev_truth = truth

    def _integrate_odometry(self, r: _Robot, truth: np.ndarray, dt: float) -> None:
        """Wheel distances of the true motion, corrupted by the configured errors, integrated."""
        n = self.config.odometry
        track = self.config.drive.track
        c, s = np.cos(r.prev_truth[2]), np.sin(r.prev_truth[2])
        dx, dy = truth[0] - r.prev_truth[0], truth[1] - r.prev_truth[1]
        ds = c * dx + s * dy
        dth = float(wrap_angle(truth[2] - r.prev_truth[2]))
        wheels = np.array([ds - dth * track / 2, ds + dth * track / 2])
        wheels = wheels * (1 + np.array([n.scale_error_left, n.scale_error_right]))
        wheels += self.rng.standard_normal(2) * np.sqrt(n.k_wheel * np.abs(wheels))
        ds_o = wheels.mean()
        dth_o = (wheels[1] - wheels[0]) / (track * (1 + n.track_error))
        r.odom = compose(r.odom, np.array([ds_o * np.cos(dth_o / 2), ds_o * np.sin(dth_o / 2), dth_o]))
        r.odom_twist = np.array([ds_o / dt, dth_o / dt])

    def run_until(self, t_ns: int) -> None:
        """Step until the clock reaches ``t_ns``."""
        while self.time_ns < t_ns:
            self.step()

    def frames_due(self) -> list[str]:
        """Robots whose next stereo frame is due at the current time."""
        return [n for n, r in self.robots.items() if r.next_frame_ns <= self.time_ns]

    # ------------------------------------------------------------------ cameras
    def camera_extrinsic(self) -> np.ndarray:
        """(4, 4) base_link <- left camera optical frame."""
        cam = self.config.camera
        t = np.eye(4)
        t[:3, :3] = R_BASE_OPTICAL
        t[:3, 3] = [cam.mount_x, cam.baseline / 2, cam.mount_z]
        return t

    def camera_calibrations(self) -> tuple[CameraCalibration, CameraCalibration]:
        """Left and right CameraInfo-like calibrations of the (already rectified) renderings."""
        cam = self.config.camera
        f = self._fx
        cx, cy = cam.width / 2 - 0.5, cam.height / 2 - 0.5
        k = np.array([[f, 0, cx], [0, f, cy], [0, 0, 1.0]])
        pl = np.hstack([k, np.zeros((3, 1))])
        pr = pl.copy()
        pr[0, 3] = -f * cam.baseline
        common = dict(width=cam.width, height=cam.height, K=k, D=np.zeros(5), R=np.eye(3), distortion_model="plumb_bob")
        return CameraCalibration(P=pl, **common), CameraCalibration(P=pr, **common)

    def _render(self, eye: np.ndarray, forward: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cam = self.config.camera
        view = p.computeViewMatrix(eye.tolist(), (eye + forward).tolist(), [0, 0, 1])
        _, _, rgb, depth, _ = p.getCameraImage(cam.width, cam.height, view, self._proj, renderer=p.ER_TINY_RENDERER,
                                               flags=p.ER_NO_SEGMENTATION_MASK, physicsClientId=self.client)
        rgb = np.asarray(rgb, np.uint8).reshape(cam.height, cam.width, 4)
        grey = (rgb[..., :3].astype(np.uint16) @ np.array([77, 150, 29], np.uint16) >> 8).astype(np.uint8)
        d = np.asarray(depth, np.float32).reshape(cam.height, cam.width)
        z = cam.far * cam.near / (cam.far - (cam.far - cam.near) * d)
        return grey, z.astype(np.float32)

    def render_stereo(self, name: str) -> StereoFrame:
        """Render robot ``name``'s stereo pair now and schedule its next frame."""
        r = self._robot(name)
        cam = self.config.camera
        pose = self.ground_truth(name)
        c, s = np.cos(pose[2]), np.sin(pose[2])
        forward = np.array([c, s, 0.0])
        leftward = np.array([-s, c, 0.0])
        centre = np.array([pose[0] + c * cam.mount_x, pose[1] + s * cam.mount_x, cam.mount_z])
        left, depth = self._render(centre + leftward * cam.baseline / 2, forward)
        right, _ = self._render(centre - leftward * cam.baseline / 2, forward)
        period = int(round(1e9 / cam.rate_hz))
        r.next_frame_ns = max(r.next_frame_ns + period, self.time_ns + 1)
        return StereoFrame(left, right, depth, self.time_ns)

    def laser_scan(self, name: str, num_beams: int = 181, fov: float = np.pi, max_range: float = 5.0,
                   height: float = 0.3) -> np.ndarray:
        """2D ray-cast ranges (num_beams,) [m] from base_link at ``height`` over ±fov/2;
        max_range where nothing is hit (for fast exploration runs without rendering)."""
        pose = self.ground_truth(name)
        ang = pose[2] + np.linspace(-fov / 2, fov / 2, num_beams)
        start = np.column_stack([np.full(num_beams, pose[0]), np.full(num_beams, pose[1]), np.full(num_beams, height)])
        end = start + np.column_stack([np.cos(ang), np.sin(ang), np.zeros(num_beams)]) * max_range
        hits = p.rayTestBatch(start.tolist(), end.tolist(), physicsClientId=self.client)
        frac = np.array([h[2] if h[0] not in (-1, self.robots[name].body) else 1.0 for h in hits])
        return frac * max_range

    def close(self) -> None:
        """Disconnect the physics client."""
        if self.client is not None and p.isConnected(self.client):
            p.disconnect(self.client)
        self.client = None

    def __enter__(self) -> "Simulation":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
