"""Faults in a live team run: config/demo_faults.yaml's three faults, compressed into SECONDS = 45
simulated s of its 65 (the central node killed with SIGKILL and restarted with --resume from its
checkpoint, robot2's frontend stopped for 15 s instead of 30 s: a robot gone silent, then back,
robot1's frontend killed and restarted). The yaml's two 65 s runs and their replays took 400 s of
the suite; the compressed pair exercises the same recoveries. The run completes, the central node
resumes where its checkpoint left it, and every robot's ATE stays within 1.5× of the same run
without faults. The robots drive a fixed loop steered by their true pose (``sim.route``), so both
runs see the same images and only the faults differ (with exploration, two live runs of one config
differed by up to 0.15 m without any fault).

The restarted central node receives what was published while it was down (the publishers'
transient-local history, mrslam_ros/qos.py), so no stretch of the run is lost. One run is one
draw of the particle filter: the clean recording replayed with filter seeds 0-7 gives robot1
0.027-0.043 m. So the 1.5× bound is held by the median over filter seeds, both live recordings
replayed offline (the faulted one with the live node's downtime, had it lost one), and the live
pair is held to 2.5× (a lost or misplaced robot gives 4× and more); docs/reliability.md."""

import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
import yaml

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.live]

ROOT = Path(__file__).resolve().parents[2]
MRSLAM = str(Path(sys.executable).parent / "mrslam")


def _demo(config: Path, out: Path) -> dict:
    proc = subprocess.run([MRSLAM, "demo", "--config", str(config), "--out", str(out)], capture_output=True, text=True,
                          timeout=900)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return json.loads((out / "report.json").read_text())


SECONDS = 45.0
#: the central node's kill [s], robot2's silence [s, s] and robot1's frontend kill [s]
KILL_SLAM, PAUSE, PAUSE_END, KILL_FRONTEND = 8.0, 16.0, 31.0, 24.0
FAULTS = [{"at": KILL_SLAM, "node": "slam", "action": "kill", "duration": 1.0},
          {"at": PAUSE, "node": "robot2/frontend", "action": "pause", "duration": PAUSE_END - PAUSE},
          {"at": KILL_FRONTEND, "node": "robot1/frontend", "action": "kill", "duration": 1.0}]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("faults")
    cfg = yaml.safe_load((ROOT / "config" / "demo_faults.yaml").read_text())
    # the yaml's faults, in the same order, at the compressed times
    assert [(f["node"], f["action"]) for f in cfg["faults"]] == [(f["node"], f["action"]) for f in FAULTS]
    cfg["team"]["seconds"] = SECONDS
    cfg["faults"] = FAULTS
    (tmp / "faults.yaml").write_text(yaml.safe_dump(cfg))
    cfg["faults"] = []
    (tmp / "clean.yaml").write_text(yaml.safe_dump(cfg))
    faulty = _demo(tmp / "faults.yaml", tmp / "faults")
    clean = _demo(tmp / "clean.yaml", tmp / "clean")
    return tmp, faulty, clean


def test_every_fault_was_injected_and_the_run_completed(runs):
    tmp, faulty, _ = runs
    assert [(f.get("fault") or "recover", f["node"]) for f in faulty["faults"]] == [
        ("kill", "slam"), ("recover", "slam"), ("pause", "robot2/frontend"), ("kill", "robot1/frontend"),
        ("recover", "robot1/frontend"), ("recover", "robot2/frontend")]
    assert faulty["failed_nodes"] == []
    assert all(code == 0 for code in faulty["exit_codes"].values()), faulty["exit_codes"]
    log = (tmp / "faults" / "logs" / "slam.log").read_text()
    assert "resumed from" in log


def test_the_resumed_central_node_kept_the_trajectories_from_before_the_kill(runs):
    tmp, _, _ = runs
    est = np.load(tmp / "faults" / "slam" / "estimates.npz")
    for robot in ("robot1", "robot2"):
        t = est[f"{robot}.t"] * 1e-9
        # from before the central node's kill to past the last fault's end (not to the end: a
        # central node that lags on a loaded machine is stopped with its last seconds queued)
        assert t.min() < KILL_SLAM - 3.0 and t.max() > SECONDS - 10.0, robot
        # the central node adds at most 5 s (its re-localisation tries) to any silence of the robot's
        # sets: robot2's frontend publishes again some seconds after its pause ends, the more the
        # more loaded the machine (39.4 s instead of 31 s in one CI run)
        sets = _set_stamps(tmp / "faults" / "bag", robot)
        assert np.diff(t).max() < np.diff(sets).max() + 5.0, robot
    t2 = est["robot2.t"] * 1e-9
    # robot2 was silent: no updates in between, updates again after it came back
    assert not ((t2 > PAUSE + 2.0) & (t2 < PAUSE_END - 3.0)).any() and (t2 > PAUSE_END + 1.0).sum() >= 30


def _set_stamps(bag: Path, robot: str) -> np.ndarray:
    """The stamps [s] of the observation sets ``robot``'s frontend published (the bag's)."""
    from mrslam_ros.conversions import stamp_to_ns
    from mrslam_ros.runlog import deserialize, read_bag

    topic = f"/{robot}/observations"
    return np.array([stamp_to_ns(deserialize(m.data, m.msgtype).header.stamp) * 1e-9
                     for m in read_bag(bag, {topic: robot})])


SEEDS = range(3)


def _largest_gap(run: Path) -> tuple[float, float]:
    """The longest time between two updates of robot1 before robot2's silence (the central node's
    kill, not the wait for robot2 nor robot1's frontend restart): (the update before, the update
    after) [s]."""
    t = np.load(run / "slam" / "estimates.npz")["robot1.t"] * 1e-9
    t = t[t < PAUSE]
    i = int(np.argmax(np.diff(t)))
    return float(t[i]), float(t[i + 1])


def test_the_restarted_central_node_caught_up_on_what_it_missed(runs):
    # the odometry and observation sets published while it was down come from the publishers'
    # transient-local history (mrslam_ros/qos.py): no update is missing around the kill
    tmp, _, _ = runs
    before, after = _largest_gap(tmp / "faults")
    assert after - before < 0.5, (before, after)


def _replay(run: Path, out: Path, seed: int, downtime: tuple[float, float] | None) -> dict:
    cmd = [MRSLAM, "replay", str(run / "bag"), "--offline", "--quiet", "--seed", str(seed), "--out", str(out)]
    if downtime:
        cmd += ["--downtime", f"{downtime[0] + 0.05:.2f}:{downtime[1] - 0.2:.2f}"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    return {n: r["ate_rmse_m"] for n, r in json.loads((out / "report.json").read_text())["robots"].items()}


@pytest.fixture(scope="module")
def seeds(runs):
    """Per robot, the ATE of each filter seed on the faulted (with its downtime) and the clean recording."""
    tmp, _, _ = runs
    down = _largest_gap(tmp / "faults")  # replayed as a downtime if the live node lost that stretch
    if down[1] - down[0] < 1.0:
        down = None
    jobs = [(kind, s) for kind in ("faults", "clean") for s in SEEDS]
    with ThreadPoolExecutor(2) as pool:
        ates = list(pool.map(lambda j: _replay(tmp / j[0], tmp / f"{j[0]}_seed{j[1]}", j[1],
                                               down if j[0] == "faults" else None), jobs))
    out: dict = {"faults": {}, "clean": {}}
    for (kind, _), ate in zip(jobs, ates):
        for name, v in ate.items():
            out[kind].setdefault(name, []).append(v)
    return out


def test_accuracy_over_filter_seeds_stays_within_the_bound_of_uninterrupted_runs(seeds):
    for name, faulted in seeds["faults"].items():
        assert np.median(faulted) <= 1.5 * np.median(seeds["clean"][name]), (name, seeds)


def test_the_live_run_stays_within_the_bound_for_one_draw(runs):
    tmp, faulty, clean = runs
    ratios = {name: r["ate_rmse_m"] / clean["robots"][name]["ate_rmse_m"] for name, r in faulty["robots"].items()}
    # what a failure needs to be understood from the CI log alone
    slam = json.loads((tmp / "faults" / "slam" / "slam.json").read_text())
    why = {"faulted": {n: r["ate_rmse_m"] for n, r in faulty["robots"].items()},
           "clean": {n: r["ate_rmse_m"] for n, r in clean["robots"].items()},
           "relocalizations": slam.get("relocalizations"),
           "error_by_time": {n: _error_by_time(tmp / "faults", n) for n in faulty["robots"]}}
    assert all(v <= 2.5 for v in ratios.values()), why


def _error_by_time(run: Path, robot: str, window: float = 5.0) -> list[tuple[float, float]]:
    """(start [s], mean position error [m]) of ``robot``'s estimate per ``window`` s of the run."""
    est = np.loadtxt(run / "trajectories" / f"{robot}_est.tum")
    gt = np.loadtxt(run / "trajectories" / f"{robot}_gt.tum")
    err = np.linalg.norm(est[:, 1:3] - gt[:, 1:3], axis=1)
    t = est[:, 0]
    return [(float(a), round(float(err[(t >= a) & (t < a + window)].mean()), 3))
            for a in np.arange(0.0, t.max(), window) if ((t >= a) & (t < a + window)).any()]
