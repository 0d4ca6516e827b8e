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
        node.set_parameters([Parameter("filter.num_particles", value=42), Parameter("robots", value=["robot1", "robot3"]),
                             Parameter("filter.association.candidate_search", value="spatial")])
        cfg = read_config(node, MrclamConfig)
        assert cfg.filter.num_particles == 42 and cfg.robots == ("robot1", "robot3")
        assert cfg.filter.association.candidate_search == "spatial"
        node.set_parameters([Parameter("filter.association.mode", value="hungarian")])
        with pytest.raises(ConfigError, match="^filter.association.descriptor_trust_gate = 10000.0 does nothing with mode hungarian"):
            read_config(node, MrclamConfig)  # MR.CLAM trusts barcodes by the ml rule only
        node.set_parameters([Parameter("filter.association.mode", value="ml")])
        assert cfg.duration is None
        node.set_parameters([Parameter("mode", value="solo")])
        with pytest.raises(ConfigError, match="mode: expected one of"):
            read_config(node, MrclamConfig)
        node.destroy_node()
    finally:
        rclpy.shutdown()


def test_params_file_with_nested_keys_ints_for_floats_and_typos(tmp_path):
    """`--ros-args --params-file` as the launcher writes it: nested YAML, YAML ints for float fields."""
    import rclpy
    import yaml

    from mrslam_core.configio import ConfigError
    from mrslam_core.pipelines.mrclam import MrclamConfig
    from mrslam_ros.params import declare_config, read_config, unknown_overrides

    default = MrclamConfig()
    params = {"filter": {"num_particles": 77, "motion": {"alpha1": 1}}, "robots": ["robot2", "robot4", "robot5"], "use_sim_time": True}
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump({"/**": {"ros__parameters": params}}))
    typo = tmp_path / "typo.yaml"
    # a misspelled key and section are this node's mistakes; another node's section of a shared
    # profile (a frontend's, whose key looks like one of the filter's) is not
    typo.write_text(yaml.safe_dump({"/**": {"ros__parameters": {
        "filter": {"num_particle": 5}, "fliter": {"seed": 3},
        "frontend": {"track_descriptor_gate": 0.2, "max_disparity": 128}}}}))
    rclpy.init()
    try:
        node = rclpy.create_node("params_file_test", cli_args=["--ros-args", "--params-file", str(path)])
        declare_config(node, default)
        cfg = read_config(node, MrclamConfig, strict=True)
        assert cfg.filter.num_particles == 77 and cfg.robots == ("robot2", "robot4", "robot5")
        assert cfg.filter.motion.alpha1 == 1.0 and isinstance(cfg.filter.motion.alpha1, float)
        assert cfg.filter.motion.alpha2 == default.filter.motion.alpha2  # untouched: the dataclass default
        assert node.get_parameter("use_sim_time").value is True
        node.destroy_node()
        node = rclpy.create_node("params_typo_test", cli_args=["--ros-args", "--params-file", str(typo)])
        declare_config(node, default)
        assert unknown_overrides(node) == ["filter.num_particle", "fliter.seed"]
        with pytest.raises(ConfigError, match="did you mean filter.num_particles"):
            read_config(node, MrclamConfig, strict=True)
        assert read_config(node, MrclamConfig).filter.num_particles == default.filter.num_particles  # warned only
        node.destroy_node()
        bad = tmp_path / "bad.yaml"
        bad.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"filter": {"motion": {"alpha1": "high"}}}}}))
        node = rclpy.create_node("params_bad_test", cli_args=["--ros-args", "--params-file", str(bad)])
        declare_config(node, default)
        with pytest.raises(ConfigError, match="filter.motion.alpha1: expected a number"):
            read_config(node, MrclamConfig)
        node.destroy_node()
    finally:
        rclpy.shutdown()


def test_an_empty_float_array_default_takes_a_params_file_list(tmp_path):
    """sim.route.waypoints defaults to () (no route): declared as a double array, then set."""
    import rclpy
    import yaml

    from mrslam_ros.params import declare_config, read_config
    from mrslam_ros.sim_node import SimNodeConfig

    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"sim": {"route": {"waypoints": [1.0, 1.0, 2.0, 1.0, 2.0, 2.5]}}}}}))
    rclpy.init()
    try:
        node = rclpy.create_node("params_empty_default")
        declare_config(node, SimNodeConfig())
        assert read_config(node, SimNodeConfig).sim.route.waypoints == ()
        node.destroy_node()
        node = rclpy.create_node("params_route", cli_args=["--ros-args", "--params-file", str(path)])
        declare_config(node, SimNodeConfig())
        assert read_config(node, SimNodeConfig).sim.route.waypoints == (1.0, 1.0, 2.0, 1.0, 2.0, 2.5)
        node.destroy_node()
    finally:
        rclpy.shutdown()
