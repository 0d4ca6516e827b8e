"""``mrslam bench filter``: time of a full team step of the multi-robot filter.

Synthetic stereo world, K robots, B observations per robot and step, a map of N landmarks already
held by every particle (shared from a common ancestor, each particle's own near the robots); a step = every robot's motion sample, association, EKF updates, new
landmarks and weighting, plus resampling when due. Single-threaded: numpy and the filter's numba
kernels (compiled on first use and cached; set OMP/OPENBLAS threads to 1 before numpy loads for a
one-core figure).
"""

from __future__ import annotations

import argparse
import json
import resource
import time
from pathlib import Path

import numpy as np

from mrslam_core.datasets.synthetic import SyntheticWorld, SyntheticWorldConfig
from mrslam_core.slam.config import AssociationConfig, FilterConfig
from mrslam_core.slam.filter import MultiRobotFastSLAM


def prefill(slam: MultiRobotFastSLAM, world: SyntheticWorld, sigma: float, seed: int) -> None:
    """Give the particles the world's landmarks as a running filter holds them: one map inherited
    from a common ancestor (noisy means, isotropic covariance σ² [m²]), shared by every particle,
    and a copy of its own of each landmark within sensing range of a robot's start (the area
    mapped since the particles last had a common ancestor)."""
    rng = np.random.default_rng(seed)
    store = slam.landmarks
    n = world.landmarks.shape[0]
    slots = store.allocate(n, world.descriptors)
    order = np.lexsort((world.landmarks[:, 1] // 2.0, world.landmarks[:, 0] // 2.0))
    slots = slots[np.argsort(order)]  # slots in creation order are near each other, as when mapped
    common = world.landmarks + sigma * rng.standard_normal((n, 3))
    store.write(np.zeros(n, np.int64), slots, mean=common, cov=np.eye(3) * sigma**2, exists=True, count=5)
    m = slam.num_particles
    store.copy_rows(np.arange(1, m), np.zeros(m - 1, np.int64))
    store.set_reference(slots, common)
    d = np.linalg.norm(world.landmarks[:, None, :2] - world.start_poses()[None, :, :2], axis=2)
    recent = np.flatnonzero(d.min(axis=1) < world.cfg.max_range + 2.0)
    for p in range(m):  # set-up only
        noisy = world.landmarks[recent] + sigma * rng.standard_normal((recent.size, 3))
        store.write(np.full(recent.size, p), slots[recent], mean=noisy)
    store.refresh_reference(slots[recent])


def time_steps(
    particles: int, robots: int, landmarks: int, per_robot: int, steps: int, seed: int = 0,
    association: str = "ml", proposal: str = "fastslam1",
) -> dict:
    """Mean/p50/p95/max ms of a team step and the landmark store's memory."""
    area = landmarks / 2.0  # two landmarks per m², as in an indoor scene with a 20-feature image
    width = float(np.sqrt(area * 1.6))
    world = SyntheticWorld(
        SyntheticWorldConfig(
            num_landmarks=landmarks, width=width, height=area / width, num_robots=robots,
            max_observations=per_robot, sigma_d=1.0, sigma_r=10.0, sigma_c=10.0, seed=seed,
        )
    )
    slam = MultiRobotFastSLAM(
        FilterConfig(
            num_particles=particles, seed=seed, initial_capacity=landmarks + 1024, proposal=proposal,
            association=AssociationConfig(mode=association),
        ),
        world.robots, world.start_poses(),
    )
    prefill(slam, world, 0.05, seed)
    data = list(world.run(steps + 3))
    for _, _, _, ups in data[:3]:  # warm-up
        slam.step(ups)
    times = []
    resamples = slam.resamples
    for _, _, _, ups in data[3:]:
        t0 = time.perf_counter()
        slam.step(ups)
        times.append((time.perf_counter() - t0) * 1e3)
    t = np.array(times)
    return {
        "particles": particles, "robots": robots, "landmarks": landmarks,
        "association": association, "proposal": proposal,
        "observations_per_robot": per_robot, "steps": steps,
        "mean_ms": float(t.mean()), "p50_ms": float(np.percentile(t, 50)),
        "p95_ms": float(np.percentile(t, 95)), "max_ms": float(t.max()),
        "resample_rate": (slam.resamples - resamples) / steps,
        "store_mb": slam.landmarks.nbytes() / 2**20,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="mrslam bench filter", description=__doc__)
    ap.add_argument("--particles", type=int, default=1000)
    ap.add_argument("--robots", type=int, default=3)
    ap.add_argument("--landmarks", type=int, default=2000)
    ap.add_argument("--observations", type=int, default=20)
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--association", choices=["ml", "hungarian"], default="ml")
    ap.add_argument("--proposal", choices=["fastslam1", "fastslam2"], default="fastslam1")
    ap.add_argument("--sweep", action="store_true", help="also sweep M and map size")
    ap.add_argument("--out", default="runs/bench")
    args = ap.parse_args(argv)

    def show(r: dict) -> None:
        print(
            f"{r['association']:9s} {r['proposal']}  M={r['particles']:5d} K={r['robots']} N={r['landmarks']:6d} B={r['observations_per_robot']:3d}"
            f"  step mean {r['mean_ms']:7.1f} ms  p50 {r['p50_ms']:7.1f}  p95 {r['p95_ms']:7.1f}"
            f"  max {r['max_ms']:7.1f}  resample {r['resample_rate']:.2f}/step"
            f"  store {r['store_mb']:7.1f} MB  peak RSS {r['peak_rss_mb']:7.0f} MB", flush=True
        )

    results = {"headline": time_steps(args.particles, args.robots, args.landmarks, args.observations,
                                      args.steps, association=args.association, proposal=args.proposal)}
    show(results["headline"])
    if args.sweep:
        results["vs_particles"] = []
        for m in (100, 300, 1000, 3000):
            results["vs_particles"].append(time_steps(m, args.robots, args.landmarks, args.observations, args.steps))
            show(results["vs_particles"][-1])
        results["vs_landmarks"] = []
        for n in (2000, 20000, 200000):
            results["vs_landmarks"].append(time_steps(args.particles, args.robots, n, args.observations, args.steps,
                                                      association=args.association, proposal=args.proposal))
            show(results["vs_landmarks"][-1])
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "filter.json").write_text(json.dumps(results, indent=2))
    print(f"wrote {out / 'filter.json'}")
    return 0
