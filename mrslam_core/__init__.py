"""mrslam_core: the algorithms of mrslam (numpy/scipy/opencv/pybullet), importable without ROS."""

__version__ = "0.1.0"
