"""Stereo visual frontend: image pairs in, tracked 3D observations with descriptors out (no ROS)."""

from mrslam_core.frontend.camera import CameraCalibration, StereoRig, load_euroc_stereo
from mrslam_core.frontend.config import FrontendConfig
from mrslam_core.frontend.errors import CameraModelError, FrontendError
from mrslam_core.frontend.features import FeatureExtractor, Keypoints, descriptor_distance
from mrslam_core.frontend.frontend import Frontend, StereoFrame, image_to_grey
from mrslam_core.frontend.obstacles import ObstacleScan

__all__ = [
    "CameraCalibration", "CameraModelError", "FeatureExtractor", "Frontend", "FrontendConfig",
    "FrontendError", "Keypoints", "ObstacleScan", "StereoFrame", "StereoRig", "descriptor_distance",
    "image_to_grey", "load_euroc_stereo",
]
