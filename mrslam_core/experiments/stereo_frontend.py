"""``mrslam experiment stereo_frontend FORMAT PATH``: the stereo frontend and its visual odometry on
a real sequence with ground truth, and the stereo noise calibrated on it.

Per frame: points published (of B), and every track continued from the previous frame (each
published point's track, and every other one the frontend kept) moved into the world with the
ground-truth poses: the difference ν of its two 3D points against their published covariances
S = R₁Σ₁R₁ᵀ + R₂Σ₂R₂ᵀ, counted within the χ²(3) 99.73 % gate (νᵀS⁻¹ν ≤ 14.16) and as the NEES median
(χ²(3): 2.37). The visual odometry alone: end-point error (3D, and as a percentage of the distance
driven) and heading error at the end.

Calibration (``--calibrate``): the pixel noise (σd, σr, σc) of the stereo model (000 eq. 12) that
makes those pairs most likely, by maximum likelihood over a contaminated normal (a fraction ε of
pairs — look-alikes and wrong stereo matches the run kept, ground-truth error — drawn from the same
shape ten times wider), so the few outliers do not inflate σ. The frontend's own track gate uses
σ, so the fit is repeated on the tracks a frontend with the fitted σ keeps, until σ settles.
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np
from scipy.optimize import minimize

from mrslam_core.datasets.stereo import StereoSequence, open_sequence
from mrslam_core.experiments._output import write_tables
from mrslam_core.frontend.config import FrontendConfig
from mrslam_core.frontend.frontend import Frontend
from mrslam_core.geometry.stereo import triangulation_jacobian
from mrslam_core.pipelines.dataset import vo_endpoint

CHI2_3_3SIGMA = 14.16  # χ²(3) quantile at 99.73 %
OUTLIER_SCALE = 10.0  # standard deviations of the contaminating component, relative


@dataclasses.dataclass(frozen=True)
class TrackPairs:
    """Consecutive-frame pairs of one track, in the world frame.

    Attributes:
        nu: (P, 3) second point minus first point [m].
        jac_a, jac_b: (P, 3, 3) world-frame Jacobians of each point w.r.t. its (d, r, c) [m/px].
        sigma: (3,) the (σd, σr, σc) [px] the frontend published with.
    """

    nu: np.ndarray
    jac_a: np.ndarray
    jac_b: np.ndarray
    sigma: np.ndarray

    def covariance(self, sigma: np.ndarray) -> np.ndarray:
        """(P, 3, 3) S of the pairs under pixel noise ``sigma`` (σd, σr, σc) [px]."""
        v = np.asarray(sigma, float) ** 2
        return (np.einsum("nij,j,nkj->nik", self.jac_a, v, self.jac_a)
                + np.einsum("nij,j,nkj->nik", self.jac_b, v, self.jac_b))

    def mahalanobis2(self, sigma: np.ndarray | None = None) -> np.ndarray:
        """(P,) νᵀS⁻¹ν under ``sigma`` (default: the published σ)."""
        s = self.covariance(self.sigma if sigma is None else sigma)
        return np.einsum("ni,ni->n", self.nu, np.linalg.solve(s, self.nu[..., None])[..., 0])


def run_frontend(seq: StereoSequence, cfg: FrontendConfig) -> dict:
    """The frontend over a sequence with ground truth: points per frame, the track pairs and the
    visual odometry's poses."""
    if seq.ground_truth is None:
        raise ValueError(f"{seq.name} has no ground truth")
    rig = seq.rig
    fe = Frontend(rig, cfg)
    t_base_rect = rig.t_base_rect
    points, vo, prev = [], [], None
    nu, ja, jb = [], [], []
    for i in range(len(seq)):
        left, right = seq.read(i)
        obs, _ = fe.step(left, right, int(seq.frames[i].stamp_ns))
        if obs is None:
            prev = None
            continue
        frame = fe.last_frame
        points.append(len(obs))
        vo.append((i, fe.odometry.pose))
        world = seq.ground_truth[i] @ t_base_rect  # world <- rectified left camera
        jac = world[:3, :3] @ triangulation_jacobian(frame.xy[:, 1], frame.xy[:, 0], frame.disparity,
                                                     rig.f, rig.cx, rig.cy, rig.baseline)
        pts = frame.points @ world[:3, :3].T + world[:3, 3]
        if prev is not None:
            p_ids, p_pts, p_jac = prev
            index = {int(t): k for k, t in enumerate(p_ids)}
            for k, tid in enumerate(frame.track_ids):
                j = index.get(int(tid))
                if j is not None:
                    nu.append(pts[k] - p_pts[j])
                    ja.append(p_jac[j])
                    jb.append(jac[k])
        prev = (frame.track_ids, pts, jac)
    pairs = TrackPairs(np.array(nu).reshape(-1, 3), np.array(ja).reshape(-1, 3, 3), np.array(jb).reshape(-1, 3, 3),
                       np.array([cfg.sigma_d, cfg.sigma_r, cfg.sigma_c]))
    idx = np.array([i for i, _ in vo])
    return {"points": np.array(points), "pairs": pairs, "vo": np.array([p for _, p in vo]),
            "vo_frames": idx, "vo_failures": fe.vo_failures}


def fit_noise(pairs: TrackPairs) -> tuple[np.ndarray, float]:
    """Maximum-likelihood (σd, σr, σc) [px] and outlier fraction ε of the pairs (module docstring)."""
    k2 = OUTLIER_SCALE**2

    def nll(p: np.ndarray) -> float:
        sigma, eps = np.exp(p[:3]), 1.0 / (1.0 + np.exp(-p[3]))
        s = pairs.covariance(sigma)
        logdet = np.linalg.slogdet(s)[1]
        m2 = np.einsum("ni,ni->n", pairs.nu, np.linalg.solve(s, pairs.nu[..., None])[..., 0])
        inlier = np.log1p(-eps) - 0.5 * (logdet + m2)
        outlier = np.log(eps) - 0.5 * (logdet + 3 * np.log(k2) + m2 / k2)
        return -float(np.logaddexp(inlier, outlier).sum())

    start = np.r_[np.log(pairs.sigma), -2.0]
    res = minimize(nll, start, method="Nelder-Mead", options={"maxiter": 4000, "xatol": 1e-4, "fatol": 1e-6})
    return np.exp(res.x[:3]), float(1.0 / (1.0 + np.exp(-res.x[3])))


def evaluate(seq: StereoSequence, cfg: FrontendConfig) -> dict:
    """The figures of the module docstring for one frontend config."""
    r = run_frontend(seq, cfg)
    m2 = r["pairs"].mahalanobis2()
    pts = r["points"][cfg.min_track_length - 1:]  # the first frames cannot have tracks that long
    out = {
        "frames": int(len(r["points"])),
        "points_per_frame_mean": float(pts.mean()) if pts.size else 0.0,
        "frames_with_B_points": float(np.mean(pts >= cfg.max_observations)) if pts.size else 0.0,
        "frames_with_15_points": float(np.mean(pts >= 15)) if pts.size else 0.0,
        "track_pairs": int(m2.size),
        "pairs_within_gate": float(np.mean(m2 <= CHI2_3_3SIGMA)) if m2.size else 0.0,
        "nees_median": float(np.median(m2)) if m2.size else float("nan"),
        "vo_failures": int(r["vo_failures"]),
    }
    if len(r["vo_frames"]) > 1:
        out.update(vo_endpoint(r["vo"], seq.ground_truth[r["vo_frames"]]))
    return out | {"_pairs": r["pairs"]}


def calibrate(seq: StereoSequence, cfg: FrontendConfig, rounds: int = 3) -> tuple[FrontendConfig, list[dict]]:
    """Fit (σd, σr, σc), rerun the frontend with them, and fit again (module docstring)."""
    history = []
    for _ in range(rounds):
        pairs = run_frontend(seq, cfg)["pairs"]
        sigma, eps = fit_noise(pairs)
        history.append({"sigma_in": pairs.sigma.tolist(), "sigma_fit": sigma.tolist(), "outliers": eps,
                        "pairs": int(len(pairs.nu))})
        cfg = dataclasses.replace(cfg, sigma_d=float(sigma[0]), sigma_r=float(sigma[1]), sigma_c=float(sigma[2]))
    return cfg, history


def main(argv: list[str]) -> int:
    from mrslam_core.configio import PROFILES, load_profile
    from mrslam_core.pipelines.dataset import DatasetRunConfig

    profile = PROFILES / "real_stereo.yaml"
    ap = argparse.ArgumentParser(prog="mrslam experiment stereo_frontend", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("format")
    ap.add_argument("path")
    ap.add_argument("--config", default=str(profile), help="profile whose frontend section is used")
    ap.add_argument("--modes", nargs="+", default=["harris+usurf", "orb+orb", "sift+sift"],
                    help="detector+descriptor pairs to evaluate")
    ap.add_argument("--calibrate", action="store_true", help="also fit the stereo noise (σd, σr, σc)")
    ap.add_argument("--out", default="runs/experiments")
    args = ap.parse_args(argv)
    seq = open_sequence(args.format, args.path)
    base = load_profile(DatasetRunConfig, args.config).frontend
    rows, data = [], {"sequence": seq.name, "modes": {}}
    for mode in args.modes:
        det, desc = mode.split("+")
        cfg = dataclasses.replace(base, detector=det, descriptor=desc)
        r = evaluate(seq, cfg)
        r.pop("_pairs")
        data["modes"][mode] = r
        rows.append(f"| {mode} | {r['points_per_frame_mean']:.1f} | {100 * r['frames_with_B_points']:.0f} % | "
                    f"{100 * r['frames_with_15_points']:.0f} % | {r['track_pairs']} | {100 * r['pairs_within_gate']:.1f} % | "
                    f"{r['nees_median']:.2f} | {r.get('vo_endpoint_error_pct', float('nan')):.2f} % | "
                    f"{r.get('vo_heading_error_deg', float('nan')):+.2f}° | {r['vo_failures']} |")
    text = (f"Stereo frontend on {seq.name} ({seq.format}, {len(seq)} frames), B = {base.max_observations}, "
            f"σd/σr/σc = {base.sigma_d}/{base.sigma_r}/{base.sigma_c} px\n\n"
            "| detector+descriptor | points/frame | frames with B | frames with 15 | track pairs | within χ²(3) 99.73 % "
            "| NEES median | VO end error | VO heading | VO failures |\n|---|---|---|---|---|---|---|---|---|---|\n"
            + "\n".join(rows))
    if args.calibrate:
        _, history = calibrate(seq, base)
        data["calibration"] = history
        text += "\n\nCalibration (maximum likelihood, contaminated normal):\n\n| round | σ in (d, r, c) | σ fit | outliers |\n|---|---|---|---|\n"
        text += "\n".join(f"| {i + 1} | {', '.join(f'{v:.3f}' for v in h['sigma_in'])} | "
                          f"{', '.join(f'{v:.3f}' for v in h['sigma_fit'])} | {100 * h['outliers']:.1f} % |"
                          for i, h in enumerate(history))
    write_tables(args.out, f"stereo_frontend_{seq.name}", text, data)
    return 0
