"""``mrslam experiment particles_observations``: 000's Figure 4 in simulation.

Position error of the joint filter against the particle count M and against the observations per
robot and step B, on the synthetic stereo world with 000's setting: two robots, stereo points
with 000's pixel noise (σd = 1 px, σr = σc = 10 px), FastSLAM 1.0 with maximum-likelihood
association (000 section 5). Each run drives both robots one lap of their loop; its error is the
RMS over the run of both robots' position errors (the filter's weighted mean against ground
truth). Every (M, B) cell is run over the same seeds (world, noise and filter).

Writes ``particles_observations.md``/``.json`` and ``particles_observations.png`` (error against
M, one line per B; error against B, one line per M) under ``--out``.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

from mrslam_core.datasets.synthetic import SyntheticWorld, SyntheticWorldConfig
from mrslam_core.experiments._output import write_tables
from mrslam_core.slam.config import AssociationConfig, FilterConfig
from mrslam_core.slam.filter import MultiRobotFastSLAM

#: 000's setting: two robots, its stereo noise (section 4, eq. 12)
WORLD = SyntheticWorldConfig(num_robots=2, sigma_d=1.0, sigma_r=10.0, sigma_c=10.0)
PARTICLES = (1, 3, 10, 30, 100, 300, 1000, 2500)
OBSERVATIONS = (1, 5, 10, 20)


def lap_steps(cfg: SyntheticWorldConfig, laps: float) -> int:
    """Steps for ``laps`` laps of the synthetic world's loop."""
    ax, ay = 0.35 * cfg.width, 0.3 * cfg.height
    perimeter = np.pi * (3 * (ax + ay) - np.sqrt((3 * ax + ay) * (ax + 3 * ay)))
    return int(laps * perimeter / (cfg.speed * cfg.dt))


def run(particles: int, observations: int, seed: int, laps: float = 1.0) -> float:
    """RMS position error [m] over a run of both robots (weighted-mean estimate)."""
    world = SyntheticWorld(replace(WORLD, max_observations=observations, seed=seed))
    slam = MultiRobotFastSLAM(
        FilterConfig(num_particles=particles, seed=seed, proposal="fastslam1",
                     association=AssociationConfig(mode="ml")),
        world.robots, world.start_poses(),
    )
    sq = []
    for _, true, _, updates in world.run(lap_steps(world.cfg, laps)):
        slam.step(updates)
        sq.append(((slam.estimate().poses[:, :2] - true[:, :2]) ** 2).sum(axis=1))
    return float(np.sqrt(np.mean(sq)))


def plot(errors: dict[tuple[int, int], list[float]], particles, observations, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    med = {key: float(np.median(v)) for key, v in errors.items()}
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    panels = (  # x values, the lines (label, key of each x), x label, title, log x
        (particles, [(f"B = {bb}", [(m, bb) for m in particles]) for bb in observations],
         "particles M", "error against the particle count", True),
        (observations, [(f"M = {m}", [(m, bb) for bb in observations]) for m in particles],
         "observations per robot and step B", "error against the observations per step", False),
    )
    for ax, (xs, lines, xlabel, title, log_x) in zip(axes, panels):
        for label, keys in lines:
            ax.plot(xs, [med[key] for key in keys], marker="o", label=label)
        if log_x:
            ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.set_ylabel("RMS position error [m]")
        ax.set_title(title)
        ax.legend(ncol=1 if log_x else 2, fontsize=8)
        ax.grid(True, which="both", alpha=0.3)
    fig.suptitle("Two robots, synthetic stereo world, FastSLAM 1.0 (median over seeds)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="mrslam experiment particles_observations", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--particles", type=int, nargs="+", default=list(PARTICLES))
    ap.add_argument("--observations", type=int, nargs="+", default=list(OBSERVATIONS))
    ap.add_argument("--seeds", type=int, default=3, help="seeds 0..N-1 per cell")
    ap.add_argument("--laps", type=float, default=1.0)
    ap.add_argument("--out", default="runs/experiments")
    args = ap.parse_args(argv)
    errors: dict[tuple[int, int], list[float]] = {}
    for m in args.particles:
        for b in args.observations:
            errors[(m, b)] = [run(m, b, s, args.laps) for s in range(args.seeds)]
            print(f"M={m:5d} B={b:3d}  RMS error " + " ".join(f"{e:.3f}" for e in errors[(m, b)]), flush=True)
    head = "| M | " + " | ".join(f"B = {b}" for b in args.observations) + " |"
    lines = [f"RMS position error [m], median (min–max) over seeds 0–{args.seeds - 1}, {args.laps:g} lap(s)", "",
             head, "|---|" + "---|" * len(args.observations)]
    for m in args.particles:
        cells = []
        for b in args.observations:
            e = errors[(m, b)]
            cells.append(f"{np.median(e):.3f} ({min(e):.3f}–{max(e):.3f})")
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    data = {"particles": args.particles, "observations": args.observations, "seeds": args.seeds,
            "laps": args.laps, "errors": {f"{m},{b}": v for (m, b), v in errors.items()}}
    md = write_tables(args.out, "particles_observations", "\n".join(lines), data)
    png = md.with_suffix(".png")
    plot(errors, args.particles, args.observations, png)
    print(f"wrote {png}")
    return 0
