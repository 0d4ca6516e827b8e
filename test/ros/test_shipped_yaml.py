"""Every YAML (and layout) file the project ships loads into what reads it: the profiles into every
node and pipeline config that takes their sections, the launch files, the demo configs, the
worlds, the bags' node parameters; and no shipped file is left without a loader here."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest
import yaml

from mrslam_core.configio import _profile_parameters, load_profile, load_yaml

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[2]
PROFILES = ("sim_team.yaml", "real_stereo.yaml", "mrclam.yaml")


def _readers() -> list[type]:
    """Every config that reads a profile: the nodes' and the offline pipelines'."""
    from mrslam_core.pipelines.dataset import DatasetRunConfig
    from mrslam_core.pipelines.mrclam import MrclamConfig
    from mrslam_core.pipelines.team import TeamConfig
    from mrslam_ros.explore_node import ExploreNodeConfig
    from mrslam_ros.frontend_node import FrontendNodeConfig
    from mrslam_ros.sim_node import SimNodeConfig
    from mrslam_ros.slam_node import SlamNodeConfig
    from mrslam_ros.view_node import ViewNodeConfig

    return [SimNodeConfig, FrontendNodeConfig, SlamNodeConfig, ExploreNodeConfig, ViewNodeConfig, TeamConfig,
            MrclamConfig, DatasetRunConfig]


@pytest.mark.parametrize("name", PROFILES)
def test_a_profile_loads_into_every_config_that_reads_it_and_each_section_has_a_reader(name):
    path = REPO / "config" / name
    sections = set(_profile_parameters(path))
    read = set()
    for cls in _readers():
        mine = sections & {f.name for f in dataclasses.fields(cls)}
        load_profile(cls, path)  # raises ConfigError naming a wrong key or value
        read |= mine
    assert sections == read, f"{name}: no config reads {sorted(sections - read)}"


def _launch(path: Path) -> None:
    import importlib

    from mrslam_core.configio import from_dict
    from mrslam_ros.launch import LaunchConfig

    cfg = load_yaml(LaunchConfig, path)
    assert cfg.nodes, path
    for spec in cfg.nodes:
        module = importlib.import_module(spec.module)
        (cls,) = [c for n, c in vars(module).items() if n.endswith("NodeConfig") and dataclasses.is_dataclass(c)]
        from_dict(cls, spec.params)


def _demo(path: Path) -> None:
    from mrslam_ros.demo import DemoConfig

    load_yaml(DemoConfig, path)


def _world(path: Path) -> None:
    from mrslam_core.sim.world import load_world

    assert load_world(path).start_poses.shape[1] == 3


def _slam_params(path: Path) -> None:
    from mrslam_ros.slam_node import SlamNodeConfig

    load_yaml(SlamNodeConfig, path)


def _profile(path: Path) -> None:
    assert path.name in PROFILES  # loaded above, into every reader


def _rosbag_metadata(path: Path) -> None:
    from mrslam_ros.bag import bag_info

    assert bag_info(path.parent).count > 0


#: (glob relative to the repository, loader)
LOADERS = [
    ("config/launch_*.yaml", _launch),
    ("config/demo_*.yaml", _demo),
    ("config/sim_team.yaml", _profile),
    ("config/real_stereo.yaml", _profile),
    ("config/mrclam.yaml", _profile),
    ("config/*.rviz", lambda p: yaml.safe_load(p.read_text())["Visualization Manager"]),
    ("config/*.json", lambda p: json.loads(p.read_text())["content"]),
    ("mrslam_core/sim/worlds/*.yaml", _world),
    ("bags/*/slam.yaml", _slam_params),
    ("bags/*/bag/metadata.yaml", _rosbag_metadata),
]


def _shipped() -> set[Path]:
    out = set()
    for folder in ("config", "mrslam_core", "mrslam_ros", "bags"):
        for pattern in ("*.yaml", "*.yml", "*.rviz", "*.json"):
            out |= {p for p in (REPO / folder).rglob(pattern) if "__pycache__" not in p.parts}
    return out


@pytest.mark.parametrize("pattern, load", LOADERS, ids=[p for p, _ in LOADERS])
def test_shipped_files_load(pattern, load):
    files = sorted(REPO.glob(pattern))
    assert files, pattern
    for path in files:
        load(path)


def test_every_shipped_config_file_has_a_loader_here():
    covered = {p for pattern, _ in LOADERS for p in REPO.glob(pattern)}
    assert _shipped() - covered == set(), "add a loader for these to LOADERS"


def test_an_installed_package_carries_the_config_folder():
    """pyproject.toml installs every file of config/ into share/mrslam/config, where
    configio.PROFILES looks when the package does not run from a checkout."""
    import tomllib

    data_files = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["data-files"]
    installed = {p for pattern in data_files["share/mrslam/config"] for p in REPO.glob(pattern)}
    assert installed == {p for p in (REPO / "config").iterdir() if p.is_file()}
