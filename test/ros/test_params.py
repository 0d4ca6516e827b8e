"""Parameters declared from config dataclasses, overridden like a params file would, read back."""

import pytest

pytestmark = pytest.mark.ros


def test_declare_override_and_read_back():
    import rclpy
    from rclpy.parameter import Parameter

    from mrslam_core.configio import ConfigError
    from mrslam_core.pipelines.mrclam import MrclamConfig
    from mrslam_ros.params import declare_config, read_config

    rclpy.init()
    try:
        node = rclpy.create_node("params_test")
        declare_config(node, MrclamConfig())
        assert node.get_parameter("filter.motion.alpha1").value == MrclamConfig().filter.motion.alpha1
        node.set_parameters([Parameter("filter.num_particles", value=42), Parameter("robots", value=[1, 3]),
                             Parameter("filter.association.mode", value="hungarian")])
        cfg = read_config(node, MrclamConfig)
        assert cfg.filter.num_particles == 42 and cfg.robots == (1, 3)
        assert cfg.filter.association.mode == "hungarian"
        assert cfg.duration is None
        node.set_parameters([Parameter("mode", value="solo")])
        with pytest.raises(ConfigError, match="mode: expected one of"):
            read_config(node, MrclamConfig)
        node.destroy_node()
    finally:
        rclpy.shutdown()
