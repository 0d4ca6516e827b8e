"""Configuration of the stereo visual frontend (the only place its defaults are written)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import cv2


#: E0 of frame-to-frame tracking per descriptor, squared distance of unit vectors. U-SURF and
#: SIFT 0.5 (000's E0 for U-SURF); ORB 0.78: a Hamming distance of 50 of 256 bits (4·50/256),
#: ORB-SLAM's threshold of a good match (TH_LOW; Mur-Artal et al. 2015). With 0.5 (32 bits),
#: half of the ORB corners the KITTI excerpt's next frame found again at the right pixel were
#: not continued (docs/results.md).
TRACK_DESCRIPTOR_GATE = {"usurf": 0.5, "sift": 0.5, "orb": 0.78}


@dataclass(frozen=True)
class FiducialConfig:
    """Robots that carry square fiducials, and how the frontend turns a tag seen in both images
    into a range and bearing of that robot (:mod:`mrslam_core.frontend.fiducials`). One profile
    section (``fiducials``) for the frontends, the simulator that draws the tags and the team
    pipeline.

    Each robot of ``robots`` carries the same tag on the four sides of a cube (the carrier)
    whose vertical axis is straight above its base_link: a camera at any side sees a face, and
    the point it measures is the axis, half the cube behind the face along the face's normal.

    Attributes:
        robots: the robot carrying each tag id: tag k is on ``robots[k]``; empty: no robot
            carries one and nothing is detected. A robot does not report its own tag.
        dictionary: the tag family, a name of OpenCV's predefined ArUco dictionaries
            (``DICT_4X4_50``: 6 cells across, readable from about 3 m at 228 px focal length
            with 15 cm tags; ``DICT_APRILTAG_36h11`` for AprilTags).
        tag_size: side of the tag's black square [m].
        carrier_half: distance from each tag face to the carrier's axis [m]; 0: a single flat
            tag whose centre is the point measured.
        carrier_height: height of the tag centres above the floor [m]: a detection whose
            triangulated centre lies elsewhere is not a robot's tag (counted ``tag_height``).
        height_tolerance: how far a real carrier may sit from ``carrier_height`` as the camera
            sees it (mounting, floor tilt) [m]; the height check is χ²(1) at 0.999 on the
            triangulated height's variance plus this squared.
        sigma_px: a detected corner's noise per image axis [px]; the disparity's is √2 times.
        normal_sigma_px: error of a face's normal from its four corners (IPPE) times the face's
            side in the image [rad·px]: the normal of a tag 15 px wide is uncertain by this / 15
            rad, and it moves the measured axis sideways by ``carrier_half`` times that
            (measured in the simulator, docs/results.md).
        row_tolerance: a tag's corners in the left and right rectified images must share their
            rows within this [px], and its corners' layout agree within twice this (else they
            are not one face, counted ``tag_unpaired``).
    """

    robots: tuple[str, ...] = ()
    dictionary: str = "DICT_4X4_50"
    tag_size: float = 0.15
    carrier_half: float = 0.10
    carrier_height: float = 0.60
    height_tolerance: float = 0.05
    sigma_px: float = 0.5
    normal_sigma_px: float = 2.0
    row_tolerance: float = 2.0

    def __post_init__(self) -> None:
        if not self.dictionary.startswith("DICT_") or not hasattr(cv2.aruco, self.dictionary):
            raise ValueError(f"dictionary must name an OpenCV ArUco dictionary (DICT_...), got {self.dictionary!r}")
        if len(set(self.robots)) != len(self.robots) or not all(isinstance(r, str) and r for r in self.robots):
            raise ValueError(f"robots must be distinct non-empty names, got {self.robots!r}")
        for name in ("tag_size", "carrier_height", "sigma_px", "row_tolerance"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0")
        for name in ("carrier_half", "height_tolerance", "normal_sigma_px"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0")
        if self.carrier_half > 0 and self.tag_size > 2 * self.carrier_half:
            raise ValueError("tag_size must fit on a carrier face (<= 2 carrier_half)")


@dataclass(frozen=True)
class FrontendConfig:
    """Stereo frontend of 000 (sections 3.2, 4, 6.1): detect, describe, match, triangulate, track.

    Descriptor distances are the squared Euclidean distance (000 eq. 16) between UNIT-norm float
    vectors, so every type lies in [0, 4] and E0 means the same thing across types (binary ORB
    strings are mapped to ±1/√256 per bit, so the distance is 4 × the normalised Hamming distance).

    Attributes:
        detector: ``harris`` (the paper's choice), ``orb`` or ``sift`` (OpenCV).
        descriptor: ``usurf`` (upright SURF, 64-d, the paper's choice), ``orb`` (256 bits) or
            ``sift`` (128-d).
        max_features: detections kept per left image, strongest first.
        orb_levels: pyramid levels of the ORB detector. 1: a frame-to-frame frontend needs the
            corners' positions to the pixel (a corner of pyramid level k is located to 1.2^k px),
            not their scale, which barely changes between frames (KITTI excerpt, ORB points
            published a frame: 8 levels 15.6, 1 level 19.9; docs/results.md).
        harris_block_size: Harris window [px].
        harris_k: Harris k.
        harris_quality: corners weaker than this fraction of the strongest are dropped.
        nms_radius: non-maximum suppression radius of Harris corners [px].
        usurf_scale: SURF scale s for detectors without a scale (Harris); window 20s [px].
        min_disparity: smallest disparity searched [px] (far limit).
        max_disparity: largest disparity searched [px] (near limit).
        patch_radius: stereo matching window half-size [px] (window 2r+1 square).
        uniqueness_ratio: reject a match unless best cost < ratio × second best cost (outside ±1
            px of the best); cost is 1 − ZNCC.
        max_match_cost: reject matches whose cost (1 − ZNCC) exceeds this.
        lr_tolerance: left-right check: the right pixel matched back must land within this
            distance of the left keypoint [px].
        discontinuity_tolerance: reject a match when the left or the right half of its window
            picks an integer disparity further than this from the whole window's [px] (a window
            across a depth discontinuity: 0 removed most wrong matches on Middlebury).
        min_texture: a left window whose grey-level standard deviation is below this is skipped.
        sigma_d: σd of the stereo observation model [px] (000: 1).
        sigma_r: σr [px] (000: 10).
        sigma_c: σc [px] (000: 10).
        min_track_length: publish a point once seen in this many consecutive frames (000: 3).
        max_observations: B, at most this many observations per frame.
        grid_cols: image grid columns for spreading the detections and the B observations.
        grid_rows: image grid rows.
        track_descriptor_gate: E0 for frame-to-frame tracking (squared distance of unit vectors);
            None: the descriptor's own (:data:`TRACK_DESCRIPTOR_GATE`).
        track_ratio: best/second-best descriptor distance ratio for tracking.
        track_radius_px: without a motion prediction (the first frames, after a motion the visual
            odometry could not estimate), the largest image motion of a point between
            consecutive frames, around the frame's common motion [px].
        track_search_px: radius in which the frame's common image motion (a turning robot) is
            looked for [px]; at most ``track_radius_px`` turns that search off.
        track_window_gate: χ² (2 dof) gate of a track's search window around its pixel predicted
            from the camera's motion (9.21: 99 %).
        keypoint_sigma_px: a keypoint's detection noise in the search window's covariance [px].
        prior_sigma_rot: standard deviation of the motion prediction per frame, per axis [rad]:
            how far this frame's camera rotation may differ from the wheel odometry's, or from
            the last frame's (constant velocity).
        prior_sigma_trans: the same for the translation, per axis [m].
        vo_gate: χ² (3 dof) gate of a continued track's 3D residual under the visual odometry's
            motion and both points' covariances; tracks outside it end (14.16: 3σ, 99.73 %).
        vo_ransac_px: PnP RANSAC inlier threshold on the reprojection error [px].
        vo_ransac_iterations: PnP RANSAC iterations.
        vo_min_inliers: fewer tracks in the gate: the frame's motion is unknown (counted in
            ``vo_failures``; the constant-velocity prior stands in, with its covariance).
        min_depth: points nearer than this along the optical axis are dropped [m].
        max_depth: points farther than this are dropped [m].
        obstacle_min_height: lower edge of the obstacle band in base_link z [m].
        obstacle_max_height: upper edge of the obstacle band in base_link z [m].
        scan_bins: bearing bins of the pseudo laser scan over the camera's field of view.
        scan_max_range: range limit of the pseudo scan [m]; bins with no return report inf.
        obstacle_source: ``dense``: block-matching disparity on a reduced image; ``features``: the
            matched feature points only.
        dense_downsample: image reduction factor of the dense obstacle disparity.
        max_track_gap: a pair later than this after the previous one starts new tracks and a new
            motion prediction (a paused or restarted camera, frames lost on a link): what the
            robot did in between is unknown to a frame-to-frame tracker, and tracks continued
            across it would carry their landmarks past the central mapper's re-localisation;
            counted as ``track_gaps`` [s].
        max_stamp_skew_ns: left/right stamps further apart than this drop the pair [ns].
        saturated_fraction: an image with more than this fraction of pixels at 0 or 255 is dropped.
    """

    detector: Literal["harris", "orb", "sift"] = "harris"
    descriptor: Literal["usurf", "orb", "sift"] = "usurf"
    max_features: int = 400
    orb_levels: int = 1
    harris_block_size: int = 3
    harris_k: float = 0.04
    harris_quality: float = 0.01
    nms_radius: int = 4
    usurf_scale: float = 1.2
    min_disparity: int = 1
    max_disparity: int = 64
    patch_radius: int = 3
    uniqueness_ratio: float = 0.8
    max_match_cost: float = 0.3
    lr_tolerance: float = 1.0
    discontinuity_tolerance: int = 0
    min_texture: float = 4.0
    sigma_d: float = 1.0
    sigma_r: float = 10.0
    sigma_c: float = 10.0
    min_track_length: int = 3
    max_observations: int = 20
    grid_cols: int = 5
    grid_rows: int = 4
    track_descriptor_gate: float | None = None
    track_ratio: float = 0.9
    track_radius_px: float = 60.0
    track_search_px: float = 160.0
    track_window_gate: float = 9.21
    keypoint_sigma_px: float = 1.0
    prior_sigma_rot: float = 0.02
    prior_sigma_trans: float = 0.05
    vo_gate: float = 14.16
    vo_ransac_px: float = 2.0
    vo_ransac_iterations: int = 100
    vo_min_inliers: int = 8
    min_depth: float = 0.2
    max_depth: float = 20.0
    obstacle_min_height: float = 0.05
    obstacle_max_height: float = 1.5
    scan_bins: int = 64
    scan_max_range: float = 8.0
    obstacle_source: Literal["dense", "features"] = "dense"
    dense_downsample: int = 2
    max_track_gap: float = 1.0
    max_stamp_skew_ns: int = 5_000_000
    saturated_fraction: float = 0.9

    @property
    def tracking_gate(self) -> float:
        """E0 of frame-to-frame tracking: ``track_descriptor_gate``, or the descriptor's own."""
        if self.track_descriptor_gate is not None:
            return self.track_descriptor_gate
        return TRACK_DESCRIPTOR_GATE[self.descriptor]

    def __post_init__(self) -> None:
        positive = (
            "max_features", "orb_levels", "harris_block_size", "usurf_scale", "patch_radius", "sigma_d",
            "sigma_r", "sigma_c", "min_track_length", "max_observations", "grid_cols",
            "grid_rows", "track_radius_px", "max_depth", "scan_bins", "scan_max_range",
            "dense_downsample", "max_track_gap", "track_window_gate", "keypoint_sigma_px", "prior_sigma_rot",
            "prior_sigma_trans", "vo_gate", "vo_ransac_px", "vo_ransac_iterations", "vo_min_inliers",
        )
        for name in positive:
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} must be > 0")
        if not 0 <= self.min_disparity < self.max_disparity:
            raise ValueError("need 0 <= min_disparity < max_disparity")
        if not 0.0 < self.uniqueness_ratio <= 1.0:
            raise ValueError("uniqueness_ratio must be in (0, 1]")
        if not 0.0 < self.max_match_cost <= 2.0:
            raise ValueError("max_match_cost must be in (0, 2] (it is 1 - ZNCC)")
        if not 0.0 < self.track_ratio <= 1.0:
            raise ValueError("track_ratio must be in (0, 1]")
        if self.track_descriptor_gate is not None and not 0.0 <= self.track_descriptor_gate <= 4.0:
            raise ValueError("track_descriptor_gate must be in [0, 4] (unit descriptors)")
        if not 0.0 <= self.min_depth < self.max_depth:
            raise ValueError("need 0 <= min_depth < max_depth")
        if self.obstacle_min_height >= self.obstacle_max_height:
            raise ValueError("obstacle_min_height must be below obstacle_max_height")
        if not 0.0 < self.saturated_fraction <= 1.0:
            raise ValueError("saturated_fraction must be in (0, 1]")
        if self.discontinuity_tolerance < 0 or self.lr_tolerance < 0:
            raise ValueError("discontinuity_tolerance and lr_tolerance must be >= 0")
        if self.max_stamp_skew_ns < 0:
            raise ValueError("max_stamp_skew_ns must be >= 0")
