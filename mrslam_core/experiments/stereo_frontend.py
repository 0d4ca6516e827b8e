"""``mrslam experiment stereo_frontend FORMAT PATH``: the stereo frontend and its visual odometry on
a real sequence with ground truth, and the stereo noise calibrated on it.
``mrslam experiment stereo_frontend sim WORLD [WORLD ...] --calibrate``: the same pairs and
calibration on the simulated team's rendered stereo (the closed loop of ``mrslam team`` with its
profile, in each world, every robot's frames against the simulator's true poses).

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
import collections
import dataclasses
from collections.abc import Callable

import numpy as np
from scipy.optimize import minimize
from scipy.special import log_expit

from mrslam_core.datasets.stereo import StereoSequence, open_sequence
from mrslam_core.experiments._output import write_tables
from mrslam_core.frontend.config import FrontendConfig
from mrslam_core.frontend.camera import StereoRig
from mrslam_core.frontend.frontend import Frontend, StereoFrame
from mrslam_core.frontend.odometry import planar_motion
from mrslam_core.geometry.stereo import triangulation_jacobian
from mrslam_core.pipelines.dataset import vo_endpoint

CHI2_3_3SIGMA = 14.16  # χ²(3) quantile at 99.73 %
OUTLIER_SCALE = 10.0  # standard deviations of the contaminating component, relative
#: on renderings, the least camera motion [m], [rad] between two views whose track pairs are used
MIN_VIEW_CHANGE = (0.01, np.radians(0.5))


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

    @staticmethod
    def concatenate(parts: list[TrackPairs]) -> TrackPairs:
        """The pairs of ``parts`` (one or more, all published with the same σ) in one set."""
        return TrackPairs(*(np.concatenate([getattr(p, k) for p in parts]) for k in ("nu", "jac_a", "jac_b")),
                          parts[0].sigma)

    def mahalanobis2(self, sigma: np.ndarray | None = None) -> np.ndarray:
        """(P,) νᵀS⁻¹ν under ``sigma`` (default: the published σ)."""
        s = self.covariance(self.sigma if sigma is None else sigma)
        return np.einsum("ni,ni->n", self.nu, np.linalg.solve(s, self.nu[..., None])[..., 0])


class PairCollector:
    """The :class:`TrackPairs` of one frontend's frames: each track seen ``lag`` frames before,
    both points moved into the world by the true poses.

    A dropped frame (``add(None, ...)``) ends the pairs across it, as the frontend's tracks do.
    Two views less than ``min_view_change`` (translation [m], rotation [rad]) apart give no pairs:
    for renderings (:data:`MIN_VIEW_CHANGE`), whose standing robot repeats the same pixel errors,
    so their differences measure nothing of the noise between views. A real camera's still frames
    differ by its sensor noise and are kept (the default, 0).
    """

    def __init__(self, rig: StereoRig, lag: int = 1, min_view_change: tuple[float, float] = (0.0, 0.0)):
        if lag < 1:
            raise ValueError(f"lag must be >= 1, got {lag}")
        self.rig = rig
        self.min_view_change = min_view_change
        self._prev: collections.deque = collections.deque(maxlen=lag)  # (pose, ids, points, jacobians)
        self._nu: list[np.ndarray] = []
        self._ja: list[np.ndarray] = []
        self._jb: list[np.ndarray] = []

    def add(self, frame: StereoFrame | None, world_base: np.ndarray) -> None:
        """One frame: ``frame`` the frontend's (None: dropped), ``world_base`` (4, 4) the true
        world <- base_link pose at it [m]."""
        if frame is None:
            self._prev.clear()
            return
        rig = self.rig
        world = world_base @ rig.t_base_rect  # world <- rectified left camera
        jac = world[:3, :3] @ triangulation_jacobian(frame.xy[:, 1], frame.xy[:, 0], frame.disparity,
                                                     rig.f, rig.cx, rig.cy, rig.baseline)
        pts = frame.points @ world[:3, :3].T + world[:3, 3]
        if len(self._prev) == self._prev.maxlen and _view_change(self._prev[0][0], world, self.min_view_change):
            _, p_ids, p_pts, p_jac = self._prev[0]
            index = {int(t): k for k, t in enumerate(p_ids)}
            pairs = [(k, index[int(t)]) for k, t in enumerate(frame.track_ids) if int(t) in index]
            if pairs:
                k, j = np.array(pairs).T
                self._nu.append(pts[k] - p_pts[j])
                self._ja.append(p_jac[j])
                self._jb.append(jac[k])
        self._prev.append((world, frame.track_ids, pts, jac))

    def pairs(self, sigma: np.ndarray) -> TrackPairs:
        """The pairs so far; ``sigma`` (3,) the (σd, σr, σc) [px] the frontend published with."""
        def stack(parts: list[np.ndarray], shape: tuple[int, ...]) -> np.ndarray:
            return np.concatenate(parts) if parts else np.zeros((0, *shape))

        return TrackPairs(stack(self._nu, (3,)), stack(self._ja, (3, 3)), stack(self._jb, (3, 3)),
                          np.asarray(sigma, float))


def _view_change(a: np.ndarray, b: np.ndarray, least: tuple[float, float]) -> bool:
    """Whether camera poses ``a`` and ``b`` (4, 4) differ by at least ``least`` (translation [m]
    or rotation [rad])."""
    rel = np.linalg.solve(a, b)
    angle = np.arccos(np.clip((np.trace(rel[:3, :3]) - 1.0) / 2.0, -1.0, 1.0))
    return bool(np.linalg.norm(rel[:3, 3]) >= least[0] or angle >= least[1])


def _sigma(cfg: FrontendConfig) -> np.ndarray:
    return np.array([cfg.sigma_d, cfg.sigma_r, cfg.sigma_c])


def _with_sigma(cfg: FrontendConfig, sigma: np.ndarray) -> FrontendConfig:
    return dataclasses.replace(cfg, sigma_d=float(sigma[0]), sigma_r=float(sigma[1]), sigma_c=float(sigma[2]))


def run_frontend(seq: StereoSequence, cfg: FrontendConfig, lag: int = 1) -> dict:
    """The frontend over a sequence with ground truth: points per frame, the track pairs (a
    track's points ``lag`` frames apart) and the visual odometry's poses."""
    if seq.ground_truth is None:
        raise ValueError(f"{seq.name} has no ground truth")
    fe = Frontend(seq.rig, cfg)
    collector = PairCollector(seq.rig, lag)
    points, vo = [], []
    for i in range(len(seq)):
        left, right = seq.read(i)
        obs, _ = fe.step(left, right, int(seq.frames[i].stamp_ns))
        collector.add(None if obs is None else fe.last_frame, seq.ground_truth[i])
        if obs is None:
            continue
        points.append(len(obs))
        vo.append((i, fe.odometry.pose))
    idx = np.array([i for i, _ in vo])
    return {"points": np.array(points), "pairs": collector.pairs(_sigma(cfg)), "vo": np.array([p for _, p in vo]),
            "vo_frames": idx, "vo_failures": fe.vo_failures}


def fit_noise(pairs: TrackPairs) -> tuple[np.ndarray, float]:
    """Maximum-likelihood (σd, σr, σc) [px] and outlier fraction ε of the pairs (module docstring)."""
    if len(pairs.nu) < 10:
        raise ValueError(f"{len(pairs.nu)} track pairs: too few to fit the stereo noise")
    k2 = OUTLIER_SCALE**2

    def nll(p: np.ndarray) -> float:
        s = pairs.covariance(np.exp(np.clip(p[:3], -20.0, 20.0)))  # the simplex may step far out
        logdet = np.linalg.slogdet(s)[1]
        m2 = np.einsum("ni,ni->n", pairs.nu, np.linalg.solve(s, pairs.nu[..., None])[..., 0])
        inlier = log_expit(-p[3]) - 0.5 * (logdet + m2)  # log(1 - ε), ε = expit(p[3])
        outlier = log_expit(p[3]) - 0.5 * (logdet + 3 * np.log(k2) + m2 / k2)
        return -float(np.logaddexp(inlier, outlier).sum())

    start = np.r_[np.log(pairs.sigma), -2.0]
    res = minimize(nll, start, method="Nelder-Mead", options={"maxiter": 4000, "xatol": 1e-4, "fatol": 1e-6})
    return np.exp(res.x[:3]), float(np.exp(log_expit(res.x[3])))


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


def calibrate(collect: Callable[[FrontendConfig], TrackPairs], cfg: FrontendConfig,
              rounds: int = 3) -> tuple[FrontendConfig, list[dict]]:
    """Fit (σd, σr, σc) to the pairs ``collect(cfg)`` gives, collect again with the fitted σ, and
    fit again (module docstring)."""
    history = []
    for _ in range(rounds):
        pairs = collect(cfg)
        sigma, eps = fit_noise(pairs)
        m2 = pairs.mahalanobis2()
        history.append({"sigma_in": pairs.sigma.tolist(), "sigma_fit": sigma.tolist(), "outliers": eps,
                        "pairs": int(len(pairs.nu)), "nees_median": float(np.median(m2)) if m2.size else float("nan")})
        cfg = _with_sigma(cfg, sigma)
    return cfg, history


def sim_pairs(worlds: list[str], seconds: float, cfg: FrontendConfig, lag: int = 1) -> TrackPairs:
    """The track pairs (points ``lag`` frames apart) of every robot of the simulated team
    (``TeamConfig``'s defaults, frontend ``cfg``, the simulator's seed 0) in each of ``worlds``
    over ``seconds`` simulated s, against the simulator's true poses."""
    from mrslam_core.pipelines.team import TeamConfig
    from mrslam_core.pipelines.team import run as run_team

    base = TeamConfig(seconds=seconds)
    parts = []
    for world in worlds:
        collectors: dict[str, PairCollector] = {}

        def on_frame(robot: str, fe: Frontend, truth: np.ndarray, dropped: bool) -> None:
            c = collectors.setdefault(robot, PairCollector(fe.rig, lag, MIN_VIEW_CHANGE))
            c.add(None if dropped else fe.last_frame, planar_motion(truth))  # world <- base_link

        run_team(dataclasses.replace(base, sim=dataclasses.replace(base.sim, world=world), frontend=cfg),
                 on_frame=on_frame)
        parts += [c.pairs(_sigma(cfg)) for c in collectors.values()]
    return TrackPairs.concatenate(parts)


def _calibration_table(history: list[dict]) -> str:
    return ("\n\nCalibration (maximum likelihood, contaminated normal):\n\n"
            "| round | σ in (d, r, c) [px] | pairs | NEES median at σ in | σ fit | outliers |\n|---|---|---|---|---|---|\n"
            + "\n".join(f"| {i + 1} | {', '.join(f'{v:.3f}' for v in h['sigma_in'])} | {h['pairs']} | "
                        f"{h['nees_median']:.2f} | {', '.join(f'{v:.3f}' for v in h['sigma_fit'])} | "
                        f"{100 * h['outliers']:.1f} % |" for i, h in enumerate(history)))


def _main_sim(args: argparse.Namespace) -> int:
    from mrslam_core.pipelines.team import TeamConfig

    base = TeamConfig().frontend
    _, history = calibrate(lambda c: sim_pairs(args.path, args.seconds, c, args.lag), base, args.rounds)
    text = (f"Stereo noise of the simulated team's rendered stereo: {', '.join(args.path)}, {args.seconds:g} s each, "
            f"pairs {args.lag} frame(s) apart, "
            f"every robot, the team profile's frontend (σd/σr/σc = {base.sigma_d}/{base.sigma_r}/{base.sigma_c} px)"
            + _calibration_table(history))
    write_tables(args.out, f"stereo_frontend_sim_lag{args.lag}", text,
                 {"worlds": args.path, "seconds": args.seconds, "lag": args.lag, "calibration": history})
    return 0


def main(argv: list[str]) -> int:
    from mrslam_core.configio import PROFILES, load_profile
    from mrslam_core.pipelines.dataset import DatasetRunConfig

    profile = PROFILES / "real_stereo.yaml"
    ap = argparse.ArgumentParser(prog="mrslam experiment stereo_frontend", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("format", help="kitti, euroc, or sim (the simulated team)")
    ap.add_argument("path", nargs="+", help="the sequence folder; for sim, one or more world names")
    ap.add_argument("--config", default=str(profile), help="profile whose frontend section is used (not sim: the team's)")
    ap.add_argument("--modes", nargs="+", default=["harris+usurf", "orb+orb", "sift+sift"],
                    help="detector+descriptor pairs to evaluate")
    ap.add_argument("--calibrate", action="store_true", help="also fit the stereo noise (σd, σr, σc)")
    ap.add_argument("--rounds", type=int, default=3, help="calibration rounds (each reruns the frontend)")
    ap.add_argument("--seconds", type=float, default=60.0, help="sim: simulated seconds a world")
    ap.add_argument("--lag", type=int, default=1,
                    help="calibrate on a track's points this many frames apart (errors correlated from frame to "
                         "frame fit a smaller σ at lag 1 than at larger lags)")
    ap.add_argument("--out", default="runs/experiments")
    args = ap.parse_args(argv)
    if args.format == "sim":
        return _main_sim(args)
    if len(args.path) != 1:
        ap.error(f"{args.format}: one sequence folder")
    seq = open_sequence(args.format, args.path[0])
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
        _, history = calibrate(lambda c: run_frontend(seq, c, args.lag)["pairs"], base, args.rounds)
        data["calibration"] = history
        text += _calibration_table(history)
    write_tables(args.out, f"stereo_frontend_{seq.name}", text, data)
    return 0
