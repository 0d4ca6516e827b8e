"""The central mapper's configuration: :class:`CentralConfig` and its :class:`MapCheckConfig`.

The SLAM node's parameters and the run configs' YAML keys are these field names (the node's and
the dataset run's configs extend :class:`CentralConfig`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from mrslam_core.fusion.config import FusionConfig
from mrslam_core.slam.config import FilterConfig


#: translation [m] and rotation [rad] an odometry pose may jump beyond odom_reset_speed and
#: odom_reset_turn_rate times the time since the previous pose (stamp jitter, message bursts)
ODOM_RESET_FLOOR = (0.1, 0.2)


@dataclass(frozen=True)
class MapCheckConfig:
    """Checking each robot against the older map while it drives (a robot that lost its heading).

    Every ``every`` seconds of a robot's sets, its sets of the last ``window`` seconds, moved into
    its current base_link (one point per frontend track), are aligned to the best particle's
    landmarks that are older than ``age`` (descriptor matches, RANSAC and least squares, the
    ``fusion`` thresholds but ``min_inliers``). Landmarks the robot mapped since it went wrong
    are younger and left out. Whether the robot is where its filter says or lost is then decided
    in every particle by the posterior odds of the two under the frame's likelihood against that
    particle's older landmarks (:mod:`~mrslam_core.pipelines.central.map_move`): a lost robot is
    moved to a pose drawn from the alignment, in the particles that find it lost, and the
    landmarks it made in the window since the last check that confirmed it are dropped (in every
    particle when most moved it): left in the map, they drew the moved robot straight back
    (docs/results.md, "A late loss traced"). A robot whose wheels slipped while it saw nothing
    comes back several degrees off, and then maps a corridor mapped before as a new one, turned:
    no association gate reaches landmarks 0.3 m away, while descriptors do. The same decision
    places a robot back from a gap (``relocalize_after``).

    Attributes:
        every: seconds of a robot's sets between checks; 0: off (and 0 with a filter whose
            observations are not stereo points) [s].
        window: seconds of the robot's recent sets aligned together [s]. 3 s, not 2: after a
            blind turn a robot meets few old landmarks a set, and a longer window gathers the
            inliers a fit needs (docs/results.md).
        age: only landmarks created at least this long before the check take part [s].
        min_inliers: fewest RANSAC inliers of an alignment that is weighed at all.
        lost_probability: ε, the prior probability that a robot is lost at a check (the
            contamination of its pose prior).
        outlier_probability: η, the chance that a frame point has no counterpart among its
            descriptor candidates in the older map (a landmark new to the map, a look-alike).
        candidates: descriptor candidates per frame point (nearest within the fusion's
            ``descriptor_threshold``), over which a point's likelihood is summed.
        max_shift: a lost robot is anywhere within this distance of its estimate [m].
        max_turn: and within this heading change [rad].
        sigma_xy: standard deviation per axis added to the spread of the robot's particles (the
            prior of "where the filter says"), to the alignment's covariance, and to every point
            residual (the frame's chaining error) [m].
        sigma_theta: the same for the heading [rad].
        distrust_moved: when a check moves a robot, the landmarks it made since its last
            agreeing check (all of them, if it never had one) were mapped from the wrong pose;
            later checks leave them out of the older map, so no robot is moved onto them.
        poses: what moves the window's sets into the current base_link: ``estimate``, the
            robot's filtered poses (their 2 s heading change errs 0.1–0.2° at the median, 1–5° at
            p95 in recorded runs; a robot that lost its heading still tracks its own new
            landmarks), or ``odometry`` (1–2.4° median, 5–8° p95 over 2 s in the same runs).
    """

    every: float = 1.0
    window: float = 3.0
    age: float = 10.0
    min_inliers: int = 10
    lost_probability: float = 0.01
    outlier_probability: float = 0.5
    candidates: int = 4
    max_shift: float = 1.0
    max_turn: float = 0.5
    sigma_xy: float = 0.03
    sigma_theta: float = 0.015
    poses: Literal["estimate", "odometry"] = "estimate"
    distrust_moved: bool = True

    def __post_init__(self) -> None:
        if not (0.0 < self.lost_probability < 1.0 and 0.0 < self.outlier_probability < 1.0):
            raise ValueError("lost_probability and outlier_probability must be in (0, 1)")
        if self.candidates < 1:
            raise ValueError("candidates must be >= 1")
        if self.max_shift <= 0 or self.max_turn <= 0 or self.sigma_xy <= 0 or self.sigma_theta <= 0:
            raise ValueError("max_shift, max_turn, sigma_xy and sigma_theta must be > 0")


@dataclass(frozen=True)
class CentralConfig:
    """The central mapper.

    Attributes:
        robots: robot names (topic namespaces and frame prefixes), the K axis of the filter.
        start_poses: known start poses, x y θ per robot in ``robots`` order (map frame) [m, rad].
        odom_buffer: odometry poses kept per robot for interpolation.
        max_wait: longest a set waits for the other robots' sets of the same time [s].
        max_queue: observation sets held at most; beyond it the oldest is dropped and counted.
        team_step: 0: every set is one filter step, after which the filter resamples if its
            weights have degenerated. > 0: the sets whose stamps fall in one window
            (n−1)·team_step < stamp ≤ n·team_step (stamps from 0) wait until every active robot
            has delivered a set at or after the window's end (or ``max_wait``) and are ONE filter
            step, so the filter decides on resampling once per window whatever the number of sets
            and robots in it: a resampling that one robot's weights call for draws the other
            robots' poses too, at random with respect to their own measurements, and each one
            thins out their particles (a robot nobody measures keeps the spread it needs to be
            found again only as long as that is rare). Each robot's pose is then reported once a
            window, at its last set [s].
        unknown_start: robots whose start pose is unknown (their ``start_poses`` entries are not
            used); if every robot is listed, the first one's start pose defines the map frame.
        merge_every: updates of a robot with an unknown start between attempts to align its map.
        rendezvous: the robots measure each other (sightings in their sets): a robot not merged
            also joins when it and a robot of the central filter read each other, and a weak
            alignment is held until a sighting agrees (:class:`~.lifecycle.Lifecycle`). Off: no
            second source of evidence, so every consistent alignment joins.
        sample_gap: when a robot's previous update is older than this, its motion up to 0.2 s
            before the set is applied first without observations (each particle draws its own
            motion noise), then the rest with the set: the particles then associate the set
            from distinct poses, where a FastSLAM 2.0 proposal from the one predicted pose of a
            long motion follows whatever the set matches there (a restart of the central node,
            a frame dropped by a slow frontend); 0: never [s].
        relocalize_after: a robot whose previous update is older than this (it went silent:
            a link down, a frontend restarted) is placed by its observations instead of by its
            odometry over the gap: its observation set is aligned to the best particle's map
            (descriptor matches, RANSAC and least squares, ``fusion`` thresholds) and its
            particles drawn from the fit (stereo points: 0 with another observation model);
            0: never [s].
        relocalize_tries: attempts, one a second, before a robot back from a gap is left to
            its odometry (a frame whose matches are bunched up cannot fix the rotation); its
            sets in between move it by odometry only and are counted, not mapped.
        relocalize_gate: the fit is used only within this distance of the dead-reckoned pose,
            plus ``relocalize_drift`` times the distance driven during the gap [m].
        relocalize_drift: see ``relocalize_gate`` [m/m].
        max_odom_gap: a set whose stamp falls between two odometry poses further apart than this
            is dropped (counted as ``odometry_gap``) instead of placed by interpolating across
            the hole (odometry lost while the central node was down, a driver that stalled); a
            robot turning at 0.5 rad/s at 0.35 m/s leaves a chord up to 2 cm off its arc over
            1 s, 9 cm over 2 s [s].
        odom_reset_speed: an odometry pose further from the robot's previous one than
            ``ODOM_RESET_FLOOR`` plus this speed times the time between them is an odometry
            reset (the robot's driver restarted, its odom frame is new; a robot carried while
            off): the robot is mapped on its own again from its new odometry origin and merged
            back by map alignment, as a robot with an unknown start (004 section 5); set it
            above the fastest robot of the team; 0: never [m/s].
        odom_reset_turn_rate: the same for the heading [rad/s].
        map_check: checking each robot against the older map while it drives.
        filter: the multi-robot filter (and each unknown-start robot's local filter).
        fusion: map alignment and joining of unknown-start robots.
    """

    robots: tuple[str, ...] = ("robot1",)
    start_poses: tuple[float, ...] = (0.0, 0.0, 0.0)
    odom_buffer: int = 2000
    max_wait: float = 1.0
    max_queue: int = 200
    team_step: float = 0.0
    unknown_start: tuple[str, ...] = ()
    merge_every: int = 10
    rendezvous: bool = False
    sample_gap: float = 1.0
    relocalize_after: float = 5.0
    relocalize_tries: int = 3
    relocalize_gate: float = 0.5
    relocalize_drift: float = 0.1
    max_odom_gap: float = 1.0
    odom_reset_speed: float = 2.0
    odom_reset_turn_rate: float = 6.0
    map_check: MapCheckConfig = field(default_factory=MapCheckConfig)
    filter: FilterConfig = field(default_factory=FilterConfig)
    fusion: FusionConfig = field(default_factory=FusionConfig)
