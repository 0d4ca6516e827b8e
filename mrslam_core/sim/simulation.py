"""The simulated team: pybullet physics, differential drive, wheel odometry, stereo rendering.

Frames (REP-103/105): map (x, y on the floor, z up); each robot's odom frame is its start pose;
base_link on the floor midway between the wheels (x forward, y left); the cameras' optical frames
x right, y down, z forward. Time is simulated: the clock advances one physics step at a time (ns),
as fast as the machine computes it.

Typical loop (what a ROS node does)::

    sim = Simulation(SimConfig(), load_world("office"))
    sim.add_robot("robot1"); sim.add_robot("robot2")
    while sim.time_ns < end_ns:
        sim.set_command("robot1", v, omega)
        for name in sim.step_until_frame():          # physics steps up to the next camera frame
            frame = sim.render_stereo(name)
            pose, twist = sim.odometry(name)
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pybullet as p

from mrslam_core.frontend.camera import CameraCalibration
from mrslam_core.frontend.config import FiducialConfig
from mrslam_core.frontend.fiducials import tag_image
from mrslam_core.geometry.se2 import compose, wrap_angle
from mrslam_core.sim import robot as robot_model
from mrslam_core.sim.config import SimConfig
from mrslam_core.sim.errors import SimError
from mrslam_core.sim.odometry import noisy_increment, true_increment
from mrslam_core.sim.route import RouteDriver
from mrslam_core.sim.scene import build_scene
from mrslam_core.sim.world import World, load_world

#: deepest a robot may be pushed into an obstacle by one physics step before the step is undone [m]
MAX_PENETRATION = 0.01
#: a contact whose normal is within this of perpendicular to the heading (|cos| [-], 0.57°) does
#: not block the wheels: the robot's flat side rubs along a wall or a corner, as a real one slides,
#: and a metre of it pushes in at most MAX_PENETRATION, where the depth check takes over. The dot
#: product's sign alone is decided by rounding and by the contact solver's 1e-7 rad nudges.
SLIDE_COSINE = 0.01
_LUMA = np.array([77, 150, 29], np.uint16)  # ITU-R BT.601 weights ×256


@dataclass(frozen=True)
class StereoFrame:
    """One rendered stereo pair (rectified: rows are epipolar lines).

    Attributes:
        left, right: images, (H, W) uint8 for mono8 or (H, W, 3) uint8 RGB for rgb8, rows top to
            bottom.
        depth: (H, W) float32 z-depth of every left-image pixel in the left optical frame [m];
            ``far`` where nothing was drawn.
        stamp_ns: simulated time of the exposure [ns].
        encoding: ``mono8`` or ``rgb8``.
    """

    left: np.ndarray
    right: np.ndarray
    depth: np.ndarray
    stamp_ns: int
    encoding: str


class Simulation:
    """A pybullet world with Pioneer 3-DX robots (DIRECT mode, one physics client per instance,
    so several simulations can live in one process).

    Args:
        config: simulation parameters.
        world: a parsed world; default ``load_world(config.world)``.
        fiducials: the robots that carry tags (the frontends' ``fiducials`` config): each robot
            named there gets a carrier with its tag, the others a blank one.

    Raises:
        SimError: the world cannot be loaded or pybullet cannot connect.
    """

    def __init__(self, config: SimConfig | None = None, world: World | None = None,
                 fiducials: FiducialConfig | None = None):
        self.config = config or SimConfig()
        self.fiducials = fiducials if fiducials is not None and fiducials.robots else None
        self.world = world if world is not None else load_world(self.config.world)
        self._rng = np.random.default_rng(self.config.seed)
        self._dt_ns = int(round(1e9 / self.config.physics_hz))
        self._dt = self._dt_ns * 1e-9
        self._time_ns = 0
        self._names: list[str] = []
        self._bodies: list[int] = []
        self._cmd = np.zeros((0, 2))  # commanded (v, ω)
        self._vel = np.zeros((0, 2))  # driven (v, ω) after the acceleration limits
        self._truth = np.zeros((0, 3))
        self._truth_twist = np.zeros((0, 2))
        self._odom = np.zeros((0, 3))
        self._odom_twist = np.zeros((0, 2))
        self._next_frame_ns = np.zeros(0, np.int64)
        self._route = RouteDriver(self.config.route) if self.config.route.waypoints else None
        self._tmp = tempfile.TemporaryDirectory(prefix="mrslam_sim_")
        self.client: int | None = p.connect(p.DIRECT)
        if self.client < 0:
            raise SimError("pybullet could not start a DIRECT physics client")
        cid = self.client
        p.setGravity(0, 0, 0, physicsClientId=cid)
        p.setTimeStep(self._dt, physicsClientId=cid)
        self._floor = build_scene(cid, self.world, self.config.seed, self.config.texture_density,
                                  Path(self._tmp.name))[0]
        self._urdf = Path(self._tmp.name) / "pioneer3dx.urdf"
        self._urdf.write_text(self.robot_description())
        cam = self.config.camera
        self._fx = cam.width / (2.0 * np.tan(np.radians(cam.hfov_deg) / 2))
        vfov = 2 * np.degrees(np.arctan(cam.height / (2 * self._fx)))
        self._proj = p.computeProjectionMatrixFOV(vfov, cam.width / cam.height, cam.near, cam.far)
        self._ss = cam.supersample

    # ------------------------------------------------------------------ robots
    @property
    def robot_names(self) -> list[str]:
        """Names of the robots, in the order they were added."""
        return list(self._names)

    def robot_description(self) -> str:
        """URDF text of the robots (wheels and stereo head as configured, the tag carrier if
        robots carry tags)."""
        carrier = None
        if self.fiducials is not None:
            f = self.fiducials
            if f.carrier_half <= 0:
                raise SimError("fiducials: the simulator draws tags on a carrier cube (carrier_half > 0)")
            mesh = Path(self._tmp.name) / "tag_carrier.obj"
            mesh.write_text(robot_model.carrier_mesh(f.carrier_half))
            carrier = (str(mesh), f.carrier_half, f.carrier_height)
        try:
            return robot_model.robot_description(self.config.camera, self.config.drive, carrier=carrier)
        except ValueError as exc:
            raise SimError(f"fiducials: {exc}") from None

    def _draw_tag(self, body: int, name: str) -> None:
        """Texture robot ``name``'s carrier with its tag (blank if it carries none)."""
        f, cid = self.fiducials, self.client
        link = next(j for j in range(p.getNumJoints(body, physicsClientId=cid))
                    if p.getJointInfo(body, j, physicsClientId=cid)[12].decode() == "tag_carrier")
        img = tag_image(f, f.robots.index(name)) if name in f.robots else np.full((8, 8), 255, np.uint8)
        path = Path(self._tmp.name) / f"tag_{len(self._names)}.png"
        cv2.imwrite(str(path), img)
        tex = p.loadTexture(str(path), physicsClientId=cid)
        p.changeVisualShape(body, link, textureUniqueId=tex, rgbaColor=[1, 1, 1, 1], specularColor=[0, 0, 0],
                            physicsClientId=cid)

    def add_robot(self, name: str, start_pose: np.ndarray | None = None) -> None:
        """Place a robot at ``start_pose`` (x, y, θ) in the map [m, m, rad].

        Default: the world's next unused start pose. The robot's odom frame is its start pose;
        its first stereo frame is due now.

        Raises:
            SimError: duplicate name, no start pose left, or a start pose that is not 3 finite numbers.
        """
        if not isinstance(name, str) or not name or name in self._names:
            raise SimError(f"robot name {name!r} is empty or exists already")
        if start_pose is None:
            if len(self._names) >= len(self.world.start_poses):
                raise SimError(f"world {self.world.name} has only {len(self.world.start_poses)} start poses")
            start_pose = self.world.start_poses[len(self._names)]
        start = _pose3(start_pose, "start pose")
        body = p.loadURDF(str(self._urdf), [start[0], start[1], 0.0], p.getQuaternionFromEuler([0, 0, start[2]]),
                          physicsClientId=self.client)
        p.changeDynamics(body, -1, linearDamping=0, angularDamping=0, lateralFriction=0.0,
                         physicsClientId=self.client)
        if self.fiducials is not None:
            self._draw_tag(body, name)
        self._names.append(name)
        self._bodies.append(body)
        self._cmd = np.vstack([self._cmd, np.zeros(2)])
        self._vel = np.vstack([self._vel, np.zeros(2)])
        self._truth = np.vstack([self._truth, start])
        self._truth_twist = np.vstack([self._truth_twist, np.zeros(2)])
        self._odom = np.vstack([self._odom, np.zeros(3)])
        self._odom_twist = np.vstack([self._odom_twist, np.zeros(2)])
        self._next_frame_ns = np.append(self._next_frame_ns, self._time_ns)

    def _index(self, name: str) -> int:
        try:
            return self._names.index(name)
        except ValueError:
            raise SimError(f"unknown robot {name!r}; have {self._names}") from None

    def set_command(self, name: str, v: float, omega: float) -> None:
        """Command forward speed ``v`` [m/s] and turn rate ``omega`` [rad/s] (counter-clockwise
        positive), clipped to the drive's limits; held until the next command. With a route
        (``SimConfig.route``) the route steers instead and commands are ignored.

        Raises:
            SimError: unknown robot or a non-finite command.
        """
        i = self._index(name)
        if not (np.isfinite(v) and np.isfinite(omega)):
            raise SimError(f"{name}: non-finite command ({v}, {omega})")
        d = self.config.drive
        self._cmd[i] = [np.clip(v, -d.max_speed, d.max_speed), np.clip(omega, -d.max_turn_rate, d.max_turn_rate)]

    def ground_truth(self, name: str) -> np.ndarray:
        """(3,) true pose (x, y, θ) of base_link in the map [m, m, rad]."""
        return self._truth[self._index(name)].copy()

    def place(self, name: str, pose: np.ndarray) -> None:
        """Put robot ``name`` at ``pose`` (x, y, θ) in the map [m, m, rad], at rest, as if carried
        there: its odometry does not see the move (replaying recorded ground truth for renders).

        Raises:
            SimError: unknown name or a pose that is not 3 finite numbers.
        """
        i = self._index(name)
        pose = _pose3(pose, "pose")
        self._place(self._bodies[i], pose)
        self._truth[i] = pose
        self._vel[i] = 0.0
        self._truth_twist[i] = 0.0

    def ground_truth_twist(self, name: str) -> np.ndarray:
        """(2,) true (v, ω) of base_link over the last physics step [m/s, rad/s]."""
        return self._truth_twist[self._index(name)].copy()

    def odometry(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """Wheel odometry: pose (x, y, θ) of base_link in the robot's odom frame [m, m, rad] and
        twist (v, ω) over the last physics step [m/s, rad/s], both (noisy) copies."""
        i = self._index(name)
        return self._odom[i].copy(), self._odom_twist[i].copy()

    def contacts(self, name: str) -> np.ndarray:
        """The robot's bumper: (K, 2) points (x, y) in base_link [m] where its body touches
        something other than the floor (a wall, furniture, another robot) now; at most one per
        centimetre. A contact sensor round the body (a bumper skirt), as a robot's bumper node
        reports it."""
        i = self._index(name)
        pts = [c[5][:2] for c in p.getContactPoints(bodyA=self._bodies[i], physicsClientId=self.client)
               if c[2] != self._floor]
        if not pts:
            return np.zeros((0, 2))
        pose = self._truth[i]
        c, s = np.cos(pose[2]), np.sin(pose[2])
        d = np.asarray(pts, float) - pose[:2]
        local = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])
        return np.unique(np.round(local, 2), axis=0)

    # ------------------------------------------------------------------ time
    @property
    def time_ns(self) -> int:
        """The simulated clock [ns]; 0 at construction."""
        return self._time_ns

    @property
    def physics_step_ns(self) -> int:
        """Length of one physics step [ns]."""
        return self._dt_ns

    def step(self, dt: float | None = None) -> int:
        """Advance one physics step, or ``dt`` seconds rounded to whole steps (at least one).

        Returns:
            the clock after the steps [ns].
        """
        n = 1 if dt is None else max(1, int(round(dt / self._dt)))
        for _ in range(n):
            self._physics_step()
        return self._time_ns

    def run_until(self, t_ns: int) -> None:
        """Step until the clock reaches ``t_ns`` [ns]."""
        while self._time_ns < t_ns:
            self._physics_step()

    def frames_due(self) -> list[str]:
        """Robots whose next stereo frame is due at the current time (call :meth:`render_stereo`)."""
        return [n for n, t in zip(self._names, self._next_frame_ns) if t <= self._time_ns]

    def step_until_frame(self) -> list[str]:
        """Step until at least one robot's stereo frame is due (no step if one is due now).

        Returns:
            the robots whose frame is due.

        Raises:
            SimError: no robots.
        """
        if not self._names:
            raise SimError("no robots: add one before stepping to a frame")
        self.run_until(int(self._next_frame_ns.min()))
        return self.frames_due()

    def _physics_step(self) -> None:
        """Acceleration limits, kinematic drive, contacts, then ground truth and odometry.

        The wheels do not slip sideways: a robot moves along its heading or not at all. Driving
        into an obstacle stops it (it does not slide along a wall, which no wheel odometry could
        see; a heading within :data:`SLIDE_COSINE` of parallel to the contact drives on), and
        what the contact solver does to a robot turning against an obstacle is kept only along
        its heading; a step that would push it deeper than :data:`MAX_PENETRATION` into an
        obstacle is not taken.
        """
        d, dt, cid = self.config.drive, self._dt, self.client
        depth = np.zeros(len(self._names))  # deepest contact at the current poses (negative: penetrating) [m]
        if self._names:
            if self._route is not None:
                waited = self._time_ns * 1e-9 >= self.config.route.start_interval * np.arange(len(self._names))
                for i, pose in enumerate(self._truth):
                    self._cmd[i] = self._route.command(pose) if waited[i] else (0.0, 0.0)
            lim = np.array([d.max_accel, d.max_turn_accel]) * dt
            self._vel = self._vel + np.clip(self._cmd - self._vel, -lim, lim)
            th = self._truth[:, 2]
            for i, (body, (v, w), c, s) in enumerate(zip(self._bodies, self._vel, np.cos(th), np.sin(th))):
                lin = np.array([v * c, v * s, 0.0])
                for contact in p.getContactPoints(bodyA=body, physicsClientId=cid):
                    depth[i] = min(depth[i], contact[8])
                    n = np.array([contact[7][0], contact[7][1], 0.0])  # normal on B, towards this body
                    if contact[8] < 0.005 and lin @ n < -SLIDE_COSINE * abs(v) * np.sqrt(n @ n) and n @ n > 1e-6:
                        lin[:] = 0.0  # blocked: the wheels cannot push into the obstacle
                        self._vel[i, 0] = 0.0
                p.resetBaseVelocity(body, lin.tolist(), [0.0, 0.0, w], physicsClientId=cid)
        p.stepSimulation(physicsClientId=cid)
        self._time_ns += self._dt_ns
        if not self._names:
            return
        now = np.empty_like(self._truth)
        for i, body in enumerate(self._bodies):
            pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=cid)
            yaw = p.getEulerFromQuaternion(orn)[2]
            prev = self._truth[i]
            mid = prev[2] + wrap_angle(yaw - prev[2]) / 2
            h = np.array([np.cos(mid), np.sin(mid)])
            now[i, :2] = prev[:2] + (h @ (np.array(pos[:2]) - prev[:2])) * h
            now[i, 2] = yaw
            self._place(body, now[i])
        p.performCollisionDetection(physicsClientId=cid)
        undone = False
        for i, body in enumerate(self._bodies):
            deep = min((c[8] for c in p.getContactPoints(bodyA=body, physicsClientId=cid)), default=0.0)
            if deep < -MAX_PENETRATION and deep < depth[i] - 1e-4:
                now[i] = self._truth[i]  # the step would push it deeper into an obstacle: not taken
                self._place(body, now[i])
                undone = True
        if undone:  # the next step's contacts are those of the poses kept
            p.performCollisionDetection(physicsClientId=cid)
        ds, dth = true_increment(self._truth, now)
        self._truth_twist = np.stack([ds, dth], axis=1) / dt
        inc = noisy_increment(ds, dth, self.config.odometry, d.track, self._rng)
        self._odom = compose(self._odom, inc)
        self._odom_twist = inc[:, [0, 2]] / dt
        self._truth = now

    def _place(self, body: int, pose: np.ndarray) -> None:
        """Put ``body`` at ``pose`` (x, y, θ) on the floor, upright, at rest."""
        cid = self.client
        p.resetBasePositionAndOrientation(body, [pose[0], pose[1], 0.0], p.getQuaternionFromEuler([0, 0, pose[2]]),
                                          physicsClientId=cid)

    # ------------------------------------------------------------------ cameras
    def camera_extrinsic(self, side: str = "left") -> np.ndarray:
        """(4, 4) pose of the ``side`` camera's optical frame in base_link (p_base = T · p_opt)."""
        return robot_model.camera_extrinsic(self.config.camera, side)

    def camera_infos(self) -> tuple[CameraCalibration, CameraCalibration]:
        """CameraInfo data of the left and right renderings (already rectified: D = 0, R = I).

        K = [[f, 0, W/2 − a], [0, f, H/2 − 1/s − a], [0, 0, 1]] with f = W / (2 tan(hfov/2)),
        s = supersample and a = (s − 1)/(2s): TinyRenderer samples pixel (u, v) at window
        coordinates (u, H − 1 − v), not at pixel centres, and averaging s × s blocks moves the
        sample to the block's middle; the test against the rendered depth of a slanted wall and
        the floor pins this down.
        P = [K | 0] for the left camera, P[0, 3] = −f·baseline for the right one (ROS).
        """
        cam = self.config.camera
        f = self._fx
        s = self._ss
        a = (s - 1) / (2 * s)
        k = np.array([[f, 0.0, cam.width / 2 - a], [0.0, f, cam.height / 2 - 1 / s - a], [0.0, 0.0, 1.0]])
        pl = np.hstack([k, np.zeros((3, 1))])
        pr = pl.copy()
        pr[0, 3] = -f * cam.baseline
        common = dict(width=cam.width, height=cam.height, K=k, D=np.zeros(5), R=np.eye(3), distortion_model="plumb_bob")
        return CameraCalibration(P=pl, **common), CameraCalibration(P=pr, **common)

    camera_calibrations = camera_infos

    def _render(self, eye: np.ndarray, forward: np.ndarray, want_depth: bool) -> tuple[np.ndarray, np.ndarray | None]:
        cam = self.config.camera
        s = self._ss
        w, h = cam.width * s, cam.height * s
        view = p.computeViewMatrix(eye.tolist(), (eye + forward).tolist(), [0, 0, 1])
        # ambient + diffuse only: a specular term depends on the eye and would differ between the cameras
        _, _, rgba, depth, _ = p.getCameraImage(
            w, h, view, self._proj, renderer=p.ER_TINY_RENDERER, shadow=0,
            lightDirection=[0.4, 0.6, 1.0], lightAmbientCoeff=0.6, lightDiffuseCoeff=0.45, lightSpecularCoeff=0.0,
            flags=p.ER_NO_SEGMENTATION_MASK, physicsClientId=self.client)
        rgb = np.asarray(rgba, np.uint8).reshape(h, w, 4)[..., :3]
        if s > 1:
            rgb = rgb.reshape(cam.height, s, cam.width, s, 3).mean(axis=(1, 3)).round().astype(np.uint8)
        img = np.ascontiguousarray(rgb) if cam.encoding == "rgb8" else ((rgb.astype(np.uint16) @ _LUMA) >> 8).astype(np.uint8)
        if not want_depth:
            return img, None
        # OpenGL depth buffer b ∈ [0, 1] to z-depth: z = f·n / (f − (f − n)·b)
        b = np.asarray(depth, np.float64).reshape(h, w)
        z = cam.far * cam.near / (cam.far - (cam.far - cam.near) * b)
        if s > 1:
            z = z.reshape(cam.height, s, cam.width, s).mean(axis=(1, 3))
        return img, z.astype(np.float32)

    def render_stereo(self, name: str) -> StereoFrame:
        """Render robot ``name``'s stereo pair at the current time and schedule its next frame
        one camera period after the one that was due."""
        i = self._index(name)
        cam = self.config.camera
        x, y, th = self._truth[i]
        c, s = np.cos(th), np.sin(th)
        forward = np.array([c, s, 0.0])
        leftward = np.array([-s, c, 0.0])
        centre = np.array([x + c * cam.mount_x, y + s * cam.mount_x, cam.mount_z])
        left, depth = self._render(centre + leftward * cam.baseline / 2, forward, True)
        right, _ = self._render(centre - leftward * cam.baseline / 2, forward, False)
        period = int(round(1e9 / cam.rate_hz))
        self._next_frame_ns[i] = max(self._next_frame_ns[i] + period, self._time_ns + 1)
        return StereoFrame(left, right, depth, self._time_ns, cam.encoding)

    # ------------------------------------------------------------------ other sensors
    def laser_scan(self, name: str, num_beams: int = 181, fov: float = np.pi, max_range: float = 5.0) -> np.ndarray:
        """A 2D pseudo-laser by ray casting against the collision shapes (no rendering).

        Beams from base_link at ``config.laser_height``, angles −fov/2 … fov/2 from base_link's x
        axis, counter-clockwise (as sensor_msgs/LaserScan with angle_min = −fov/2). The robot's
        own body is not seen (rays that start inside a shape ignore it); other robots are.

        Returns:
            (num_beams,) ranges [m]; ``max_range`` where nothing is hit.
        """
        if num_beams < 1 or max_range <= 0 or not 0 < fov <= 2 * np.pi:
            raise SimError("laser_scan: need num_beams >= 1, max_range > 0 and 0 < fov <= 2π")
        x, y, th = self._truth[self._index(name)]
        ang = th + np.linspace(-fov / 2, fov / 2, num_beams)
        start = np.column_stack([np.full(num_beams, x), np.full(num_beams, y), np.full(num_beams, self.config.laser_height)])
        end = start + np.column_stack([np.cos(ang), np.sin(ang), np.zeros(num_beams)]) * max_range
        frac = np.ones(num_beams)
        for k in range(0, num_beams, 16384):  # pybullet's batch limit
            hits = p.rayTestBatch(start[k:k + 16384].tolist(), end[k:k + 16384].tolist(), physicsClientId=self.client)
            frac[k:k + len(hits)] = [h[2] if h[0] >= 0 else 1.0 for h in hits]
        return frac * max_range

    def close(self) -> None:
        """Disconnect the physics client and delete the texture files."""
        if self.client is not None and p.isConnected(self.client):
            p.disconnect(self.client)
        self.client = None
        self._tmp.cleanup()

    def __enter__(self) -> "Simulation":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _pose3(value: object, what: str) -> np.ndarray:
    """``value`` as a (3,) float pose (x, y, θ); SimError unless it is 3 finite numbers."""
    pose = np.asarray(value, dtype=float).reshape(-1)
    if pose.shape != (3,) or not np.isfinite(pose).all():
        raise SimError(f"{what} must be 3 finite numbers, got {value!r}")
    return pose
