"""Run folder: TUM round trip, metrics against hand-computed values, config YAML strictness."""

import json

import numpy as np
import pytest

from mrslam_core.configio import ConfigError, from_dict, load_yaml, to_dict
from mrslam_core.evaluation.metrics import ate_rmse, interpolate_poses, longest_stay, rpe_rmse
from mrslam_core.evaluation.report import write_run
from mrslam_core.evaluation.tum import read_tum, write_tum
from mrslam_core.pipelines.mrclam import MrclamConfig
from mrslam_core.slam.config import FilterConfig


def test_tum_round_trip(tmp_path):
    t = np.array([0.0, 0.5, 1.0])
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 1.0], [-1.0, 0.5, -3.0]])
    write_tum(tmp_path / "a.tum", t, poses)
    t2, p2 = read_tum(tmp_path / "a.tum")
    np.testing.assert_allclose(t2, t)
    np.testing.assert_allclose(p2, poses, atol=1e-6)
    first = (tmp_path / "a.tum").read_text().splitlines()[0].split()
    assert len(first) == 8 and first[7] == "1.000000000"  # qw of yaw 0


def test_longest_stay():
    t = np.arange(0.0, 30.0, 0.5)
    x = np.where(t < 10, 0.3 * t, 3.0) + np.where(t > 25, t - 25, 0.0)  # drives, waits at x = 3, drives on
    xy = np.column_stack([x, 0.01 * np.sin(t)])
    # from t = 9.5 (x = 2.85, within 0.2 m of 3) until 25.0 (x = 3.0; at 25.5 it is 0.65 m away)
    assert longest_stay(t, xy, 0.2) == (pytest.approx(15.5), 19)
    assert longest_stay(t[:1], xy[:1]) == (0.0, 0)


def test_metrics_hand_computed():
    gt = np.zeros((4, 3))
    est = np.array([[3.0, 4.0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]])
    assert ate_rmse(est, gt) == pytest.approx(2.5)  # sqrt(25 / 4)
    t = np.arange(4.0)
    gt = np.column_stack([t, np.zeros(4), np.zeros(4)])
    est = np.column_stack([1.1 * t, np.zeros(4), np.zeros(4)])  # 10 % scale error
    assert rpe_rmse(t, est, gt, delta=1.0) == pytest.approx(0.1)
    np.testing.assert_allclose(interpolate_poses(np.array([0.5]), t, gt), [[0.5, 0, 0]])


def test_write_run(tmp_path):
    t = np.arange(5.0)
    gt = np.column_stack([t, t, np.zeros(5)])
    tr = {"robot1": {"t": t, "est": gt + [0.1, 0, 0], "gt": gt, "odom": gt + [0.3, 0, 0]}}
    rep = write_run(tmp_path, tr, FilterConfig(), np.array([1.0, 2.0, 3.0]),
                    {"mean": np.zeros((1, 3)), "cov": np.eye(3)[None]})
    saved = json.loads((tmp_path / "report.json").read_text())
    assert saved["robots"]["robot1"]["ate_rmse_m"] == pytest.approx(0.1)
    assert saved["robots"]["robot1"]["odom_ate_rmse_m"] == pytest.approx(0.3)
    assert saved["update_ms"]["p50"] == 2.0 and saved["landmarks"] == 1
    for f in ("robot1_est.tum", "robot1_gt.tum", "robot1_odom.tum"):
        assert (tmp_path / "trajectories" / f).is_file()
    assert {"trajectories.png", "map.png", "errors.png"} <= set(rep["plots"])
    assert from_dict(FilterConfig, saved["config"]) == FilterConfig()


def test_config_errors_name_the_key(tmp_path):
    with pytest.raises(ConfigError, match="unknown key filter.motion.alpha9"):
        from_dict(MrclamConfig, {"filter": {"motion": {"alpha9": 1}}})
    with pytest.raises(ConfigError, match="filter.num_particles: expected an integer"):
        from_dict(MrclamConfig, {"filter": {"num_particles": "many"}})
    with pytest.raises(ConfigError, match="mode: expected one of"):
        from_dict(MrclamConfig, {"mode": "solo"})
    bad = tmp_path / "x.yaml"
    bad.write_text("filter: [1, 2\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_yaml(MrclamConfig, bad)
    cfg = from_dict(MrclamConfig, {"robots": ["robot1", "robot2"], "filter": {"initial_pose_sigma": [0.1, 0.1, 0.01]}})
    assert cfg.robots == ("robot1", "robot2") and cfg.filter.initial_pose_sigma == (0.1, 0.1, 0.01)
    assert from_dict(MrclamConfig, to_dict(cfg)) == cfg


def test_shipped_config_files_load():
    from pathlib import Path

    root = Path(__file__).resolve().parents[2] / "config"
    assert load_yaml(MrclamConfig, root / "mrclam.yaml").mode == "joint"


def test_the_occupancy_grid_is_written_as_a_ros_map_file_and_plotted(tmp_path):
    from mrslam_core.exploration.mapfile import FREE, OCCUPIED, UNKNOWN, load_map_file

    prob = np.full((3, 4), 0.5)
    known = np.zeros((3, 4), bool)
    prob[0, 0], known[0, 0] = 0.1, True  # free, at the grid's origin (lower left)
    prob[2, 3], known[2, 3] = 0.9, True  # occupied, top right
    prob[1, 1], known[1, 1] = 0.5, True  # seen, neither: written unknown as map_saver does
    t = np.arange(3.0)
    tr = {"robot1": {"t": t, "est": np.zeros((3, 3)), "gt": None, "odom": None}}
    occ = {"probability": prob, "known": known, "origin": np.array([-1.0, -2.0]), "resolution": 0.1,
           "free_thresh": 0.4, "occupied_thresh": 0.65}
    rep = write_run(tmp_path, tr, FilterConfig(), np.array([1.0]), occupancy=occ)
    assert rep["occupancy_map"] == "occupancy.yaml" and "occupancy.png" in rep["plots"]
    pixels, meta = load_map_file(tmp_path / "occupancy.yaml")
    want = np.full((3, 4), UNKNOWN)
    want[0, 0], want[2, 3] = FREE, OCCUPIED
    np.testing.assert_array_equal(pixels, want)
    assert meta == {"image": "occupancy.pgm", "mode": "trinary", "resolution": 0.1, "origin": [-1.0, -2.0, 0.0],
                    "negate": 0, "occupied_thresh": 0.65, "free_thresh": 0.4}
    header = b"P5\n4 3\n255\n"
    raw = (tmp_path / "occupancy.pgm").read_bytes()
    assert raw.startswith(header) and len(raw) == len(header) + 12
    body = raw[len(header):]
    assert body[3] == OCCUPIED and body[8] == FREE  # the image's first row is the grid's top


def test_corrections_are_the_accepted_relocalisations_and_merges():
    from mrslam_core.evaluation.report import corrections

    report = {"relocalizations": [{"robot": "r1", "stamp_ns": 3_000_000_000, "cause": "map_check", "accepted": True},
                                  {"robot": "r1", "stamp_ns": 1_000_000_000, "cause": "gap", "accepted": True},
                                  {"robot": "r2", "stamp_ns": 2_000_000_000, "cause": "gap", "accepted": False}],
              "merges": [{"robot": "r3", "stamp_ns": 5_000_000_000, "accepted": True}]}
    assert corrections(report) == {"r1": [(1.0, "gap"), (3.0, "map_check")], "r3": [(5.0, "merge")]}
    assert corrections({}) == {}


def test_a_large_map_is_drawn_as_a_density_with_few_ellipses(tmp_path):
    import matplotlib.pyplot as plt

    from mrslam_core.evaluation import plots

    rng = np.random.default_rng(0)
    n = 20_000
    mean = np.column_stack([rng.uniform(0, 40, n), rng.uniform(0, 30, n), rng.uniform(0, 2, n)])
    cov = np.broadcast_to(np.diag([0.01, 0.01, 0.01]), (n, 3, 3)).copy()
    cov[:5] *= 100.0  # five uncertain landmarks: their ellipses are among the drawn ones
    t = np.arange(50) * 0.2
    est = np.column_stack([t, t, 0 * t])
    drawn = []
    real = plots.EllipseCollection

    def spy(widths, *args, **kwargs):
        drawn.append(np.asarray(widths))
        return real(widths, *args, **kwargs)

    plots.EllipseCollection = spy
    try:
        out = plots.plot_run(tmp_path, {"r1": {"t": t, "est": est, "gt": est + 0.05, "odom": None}},
                             {"mean": mean, "cov": cov}, corrections={"r1": [(2.0, "gap")]})
    finally:
        plots.EllipseCollection = real
        plt.close("all")
    assert {p.name for p in out} == {"trajectories.png", "map.png", "errors.png"}
    assert len(drawn) == 1 and len(drawn[0]) == plots.MAX_ELLIPSES
    assert np.sort(drawn[0])[-5:].min() > 0.5  # the five uncertain ones (2σ width 0.8 m) are drawn
