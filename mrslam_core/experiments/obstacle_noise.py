"""``mrslam experiment obstacle_noise [--worlds W ...] [--views N]``: the dense obstacle scan's
disparity error against the rendered depth, and the occupancy grid's ``range_noise`` it gives.

Places a robot at each start pose of each world, turned through ``--views`` headings, renders its
stereo pair and runs the obstacle scanner's block matching (``ObstacleScanner.disparity``, the
team profile's frontend). Every matched reduced pixel is compared with the depth buffer there:
true disparity f·b / z, z the mean depth of the full-resolution pixels it covers; pixels whose
depths differ by more than 2 % (a depth edge inside the pixel) or beyond ``scan_max_range`` are left
out. Per range band: the median and the robust σ (1.4826 · MAD) of the error [px]. Over all bands,
σd / (f·b) is the ``GridConfig.range_noise`` of a scan from this rig [1/m].

The scan itself (each bearing bin's nearest point in the obstacle band) is compared with the scan
of the rendered depth (``ObstacleScanner.from_depth``, each reduced pixel at the nearest depth it
covers): per band of the true range, the share of bins whose stereo range is more than 0.2 m
short of it (a false obstacle in front of the true one) or long, and the share of the bins with
an obstacle in the rendered depth where the stereo scan has none (walls without texture).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, replace

import cv2
import numpy as np

from mrslam_core.evaluation.metrics import robust_sigma
from mrslam_core.experiments._output import write_tables
from mrslam_core.frontend import FrontendConfig, StereoRig
from mrslam_core.frontend.obstacles import ObstacleScanner
from mrslam_core.pipelines.team import TeamConfig
from mrslam_core.sim.simulation import Simulation

#: the worlds measured by default: the office, and a generated warehouse and office (repetitive
#: and texture-poor walls, shelving)
WORLDS = ("office", "gen:warehouse:3:apart", "gen:office:8:together")
#: range bands of the table [m]
BANDS = (1.0, 2.0, 3.0, 4.0, 6.0, 8.0)
#: a reduced pixel whose covered depths spread more than this fraction holds a depth edge
EDGE = 0.02


@dataclass(frozen=True)
class NoiseFit:
    """Disparity error of the dense scan.

    Attributes:
        ranges: (P,) depth of every compared pixel [m].
        errors: (P,) measured − true disparity [px].
        fb: f·b of the rig [px·m].
        bins_true, bins_scan: (B,) every scan bin with a hit in both: its range in the scan of
            the rendered depth and in the stereo scan [m].
        bins_missed: (C,) every scan bin with a hit in the scan of the rendered depth and none
            in the stereo scan (a surface without texture gives no disparity): its true range [m].
    """

    ranges: np.ndarray
    errors: np.ndarray
    fb: float
    bins_true: np.ndarray
    bins_scan: np.ndarray
    bins_missed: np.ndarray

    @property
    def sigma_d(self) -> float:
        """Robust σ of the disparity error over all pixels [px]."""
        return robust_sigma(self.errors)

    @property
    def range_noise(self) -> float:
        """σd / (f·b): the grid's ``range_noise`` [1/m]."""
        return self.sigma_d / self.fb

    def bin_bands(self, off: float = 0.2) -> list[dict]:
        """Per band of the true range: scan bins hit in both, median range error [m], share of
        them more than ``off`` [m] short and long, and the share of the bins with a true obstacle
        in the band that the stereo scan missed."""
        out = []
        for lo, hi in zip(BANDS[:-1], BANDS[1:]):
            s = (self.bins_true >= lo) & (self.bins_true < hi)
            e = self.bins_scan[s] - self.bins_true[s]
            missed = int(np.count_nonzero((self.bins_missed >= lo) & (self.bins_missed < hi)))
            if len(e):
                out.append({"from_m": lo, "to_m": hi, "bins": int(len(e)), "median_m": float(np.median(e)),
                            "short": float(np.mean(e < -off)), "long": float(np.mean(e > off)),
                            "missed": missed / (missed + len(e))})
        return out

    def bands(self) -> list[dict]:
        """Per range band: pixels, median error and robust σ [px]."""
        out = []
        for lo, hi in zip(BANDS[:-1], BANDS[1:]):
            e = self.errors[(self.ranges >= lo) & (self.ranges < hi)]
            if len(e):
                out.append({"from_m": lo, "to_m": hi, "pixels": int(len(e)), "median_px": float(np.median(e)),
                            "sigma_px": robust_sigma(e)})
        return out


def measure(worlds: tuple[str, ...] = WORLDS, views: int = 8, frontend: FrontendConfig | None = None,
            seed: int = 0) -> NoiseFit:
    """The disparity error over ``views`` headings at every start pose of each of ``worlds``."""
    team = TeamConfig()
    frontend = frontend or team.frontend
    ranges, errors, bins_true, bins_scan, bins_missed = [], [], [], [], []
    fb = 0.0
    for world in worlds:
        cfg = replace(team.sim, world=world, seed=seed)
        with Simulation(cfg) as sim:
            starts = np.asarray(sim.world.start_poses, float)
            for i, start in enumerate(starts):
                sim.add_robot(f"robot{i + 1}", start)
            rig = StereoRig(*sim.camera_infos(), sim.camera_extrinsic())
            scanner = ObstacleScanner(rig, frontend)
            fb = rig.f * rig.baseline
            ds = frontend.dense_downsample
            for i, start in enumerate(starts):
                name = f"robot{i + 1}"
                for heading in start[2] + np.arange(views) * 2 * np.pi / views:
                    sim.place(name, np.array([start[0], start[1], heading]))
                    frame = sim.render_stereo(name)
                    left, right = frame.left, frame.right
                    if left.ndim == 3:
                        left, right = (cv2.cvtColor(im, cv2.COLOR_RGB2GRAY) for im in (left, right))
                    disp = scanner.disparity(left, right)
                    h, w = disp.shape
                    block = frame.depth[: h * ds, : w * ds].reshape(h, ds, w, ds)
                    z = block.mean(axis=(1, 3))
                    flat = (block.max(axis=(1, 3)) - block.min(axis=(1, 3))) <= EDGE * z
                    use = (disp > 0) & flat & (z >= frontend.min_depth) & (z <= frontend.scan_max_range)
                    ranges.append(z[use])
                    errors.append(disp[use] - fb / z[use])
                    nearest = block.min(axis=(1, 3))
                    truth = scanner.from_depth(np.where(nearest < cfg.camera.far, nearest, np.inf), 0)
                    scan = scanner.from_images(left, right, 0)
                    both = np.isfinite(truth.ranges) & np.isfinite(scan.ranges)
                    bins_true.append(truth.ranges[both])
                    bins_scan.append(scan.ranges[both])
                    bins_missed.append(truth.ranges[np.isfinite(truth.ranges) & ~np.isfinite(scan.ranges)])
    return NoiseFit(*(np.concatenate(v) for v in (ranges, errors)), float(fb),
                    *(np.concatenate(v) for v in (bins_true, bins_scan, bins_missed)))


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="mrslam experiment obstacle_noise", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--worlds", nargs="+", default=list(WORLDS))
    ap.add_argument("--views", type=int, default=8, help="headings per start pose")
    ap.add_argument("--out", default="runs/experiments")
    args = ap.parse_args(argv)
    fit = measure(tuple(args.worlds), args.views)
    lines = [f"Dense obstacle scan against the rendered depth: {', '.join(args.worlds)}, {args.views} headings "
             f"per start pose, {len(fit.errors)} pixels", "",
             "| range [m] | pixels | median error [px] | robust σ [px] |", "|---|---|---|---|"]
    for b in fit.bands():
        lines.append(f"| {b['from_m']:g}-{b['to_m']:g} | {b['pixels']} | {b['median_px']:+.3f} | {b['sigma_px']:.3f} |")
    lines += ["", f"σd {fit.sigma_d:.3f} px; f·b {fit.fb:.2f} px·m; range_noise = σd / (f·b) = {fit.range_noise:.4f} 1/m",
              "", "The scan's bins against the scan of the rendered depth:", "",
              "| true range [m] | bins | median error [m] | > 0.2 m short | > 0.2 m long | no stereo hit |",
              "|---|---|---|---|---|---|"]
    for b in fit.bin_bands():
        lines.append(f"| {b['from_m']:g}-{b['to_m']:g} | {b['bins']} | {b['median_m']:+.3f} | {100 * b['short']:.0f} % | "
                     f"{100 * b['long']:.0f} % | {100 * b['missed']:.0f} % |")
    missed = len(fit.bins_missed) / max(len(fit.bins_missed) + len(fit.bins_true), 1)
    lines += ["", f"Bins with an obstacle in the rendered depth that the stereo scan missed: {100 * missed:.0f} %"]
    write_tables(args.out, "obstacle_noise", "\n".join(lines),
                 {"sigma_d_px": fit.sigma_d, "fb": fit.fb, "range_noise": fit.range_noise, "bands": fit.bands(),
                  "bins": fit.bin_bands()})
    return 0
