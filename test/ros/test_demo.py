"""The whole suite end to end, as a user runs it: `mrslam demo` (3 robots, separate processes over
DDS, in the office), then `mrslam replay --offline` on its bag, then evo on its TUM files.

CI runs the demo for SECONDS = 20 simulated s of `make demo`'s 120 (`--seconds`): the graph, the
recording, the replay and the run folder are the same, and the suite stays within its time on the
2-core machine (the 120 s demo and its replay took 390 s of it, the 30 s one 130 s). `make demo`'s
own figures are in docs/results.md."""

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.live]

BIN = Path(sys.executable).parent

# A live run is a smoke test: DDS and thread timing change the exploration paths, so it is not
# repeatable, and its bounds must not be missable by chance. The per-robot accuracy gate is
# in-process and seeded (test/core/test_world_gate.py). Live misses are not independent per
# robot: in one CI demo a wrong map-check move of robot2 (0.41 m at 16 s) was followed by both
# teammates, and all three ended 0.30-0.37 m off (docs/results.md, "Not met yet, known limits").
# So no count of robots meeting issue 6's target is asserted here; the team's median robot must
# stay within 0.5 m (that team was at 0.35 m; a single robot of 39 demos at 0.65 m), and every
# robot within the building's scale (a robot lost by the filter is metres off).
MAX_LOST_M = 1.5
MAX_MEDIAN_ATE_M = 0.5
SECONDS = 20


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo") / "run"
    proc = subprocess.run([str(BIN / "mrslam"), "demo", "--seconds", str(SECONDS), "--out", str(out)],
                          capture_output=True, text=True, timeout=1500)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return out, json.loads((out / "report.json").read_text())


def test_every_process_ran_and_stopped_cleanly(demo_run):
    _, report = demo_run
    assert report["failed_nodes"] == []
    assert set(report["exit_codes"]) == {"sim", "robot1/frontend", "robot2/frontend", "robot3/frontend", "slam", "explore"}
    assert all(code == 0 for code in report["exit_codes"].values()), report["exit_codes"]


def test_the_team_is_localised_against_ground_truth(demo_run):
    _, report = demo_run
    assert sorted(report["robots"]) == ["robot1", "robot2", "robot3"]
    for name, r in report["robots"].items():
        assert r["poses"] >= 0.8 * 5 * SECONDS, (name, r["poses"])  # 5 Hz frames, nearly all used
        assert r["ate_rmse_m"] <= MAX_LOST_M, (name, r)
    ates = sorted(r["ate_rmse_m"] for r in report["robots"].values())
    assert ates[1] <= MAX_MEDIAN_ATE_M, report["robots"]
    # live demos explored 39-75 % of the office in 120 s; in one process the team explores 16 % by
    # 20 s and 21 % by 30 s (`mrslam team`, seed 0), 5 % standing at the start: 8 % is missed only
    # by a team that does not explore
    assert report["explored_fraction"] > 0.08


def test_the_central_node_kept_up(demo_run):
    _, report = demo_run
    u = report["update_ms"]
    assert u["count"] >= 0.8 * 3 * 5 * SECONDS
    assert u["p95"] < 200.0  # one 5 Hz frame period
    lost = {k: v for k, v in report["dropped"].items() if k in ("queue_overflow", "no_odometry_at_stamp", "odometry_gap", "stale_stamp")}
    assert sum(lost.values()) <= 3, lost


def test_the_bag_replays_offline_to_the_live_trajectories(demo_run):
    out, live = demo_run
    offline = out / "offline"
    proc = subprocess.run([str(BIN / "mrslam"), "replay", str(out / "bag"), "--offline", "--quiet", "--out", str(offline)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    report = json.loads((offline / "report.json").read_text())
    for name, diff in report["live_difference"].items():
        assert diff["poses"] >= 0.95 * diff["live_poses"], (name, diff)
        assert diff["max_m"] <= 0.05, (name, diff)
    for name in live["robots"]:
        assert abs(report["robots"][name]["ate_rmse_m"] - live["robots"][name]["ate_rmse_m"]) <= 0.05


def test_the_run_folder_opens_in_evo(demo_run):
    out, report = demo_run
    for name, r in report["robots"].items():
        tr = out / "trajectories"
        proc = subprocess.run([str(BIN / "evo_ape"), "tum", str(tr / f"{name}_gt.tum"), str(tr / f"{name}_est.tum")],
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr
        rmse = float(re.search(r"rmse\s+([0-9.eE+-]+)", proc.stdout).group(1))
        assert rmse == pytest.approx(r["ate_rmse_m"], abs=1e-3)


def test_the_run_folder_holds_the_occupancy_map_as_a_ros_map_file(demo_run):
    from mrslam_core.exploration.mapfile import FREE, OCCUPIED, load_map_file

    out, report = demo_run
    assert report["occupancy_map"] == "occupancy.yaml" and "occupancy.png" in report["plots"]
    pixels, meta = load_map_file(out / report["occupancy_map"])
    grid = report["config"]["team"]["grid"]
    assert meta["resolution"] == pytest.approx(grid["resolution"])
    # the grid grew from nothing by whole blocks on the block lattice, as far as the robots saw
    block = round(grid["block"] / grid["resolution"])
    assert pixels.shape[0] % block == 0 and pixels.shape[1] % block == 0
    corner = [v / grid["block"] for v in meta["origin"][:2]]
    assert corner == pytest.approx([round(v) for v in corner], abs=1e-6)
    free_m2 = (pixels == FREE).sum() * grid["resolution"] ** 2
    # the office has 213 m² of floor a robot can reach; the run explores more than 8 % of it (asserted
    # above), and its map file shows more than 6 % of it free
    assert free_m2 > 0.06 * 213 and (pixels == OCCUPIED).any()
