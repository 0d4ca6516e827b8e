"""``mrslam experiment mrclam_calibration DIR``: fit a MR.CLAM dataset's calibration and noise against Vicon.

What the MR.CLAM profile's sensor and motion models are fitted from (docs/results.md), for any
MR.CLAM dataset folder. The camera lines are per camera (each camera keeps its line over the
run; all MR.CLAM datasets were recorded by the same five robots); everything else pools all
robots, because it must hold for robots and datasets it was not fitted on:

- the range reading (:class:`~mrslam_core.datasets.mrclam.MrclamCalibration`): reading =
  offset + scale · z with z = r·cos b the subject's depth along the optical axis, a Huber-weighted
  line over each camera's landmark readings; each robot's readings are also predicted by the
  pooled line of the other robots (leave one robot out), and both residual spreads printed;
- each camera's bearing offset (its yaw on the robot): the median of read minus true bearing
  over its landmark readings within the robots' common Vicon span, with its readings of
  robots printed beside as a check;
- the executed share of the commanded velocity and turn rate: least squares of the Vicon
  displacement and turn over 1 s against the logged ones;
- the measurement noise: a contaminated normal (a Gaussian plus a uniform outlier density,
  fitted by EM) of the calibrated readings' range and bearing residuals, for landmarks and for
  robot sightings;
- the motion noise: the :class:`~mrslam_core.slam.config.MotionConfig` parameters that maximise
  the likelihood of the Vicon motion over every ``team_step`` window under the filter's own
  linearised motion covariance (:func:`~mrslam_core.slam.motion.predict_motion`).

It prints a table and the YAML of the fitted values (config/mrclam.yaml holds dataset 6's), and
what no causal estimator can undo: each robot's longest stretch with no measurement of or by it
(no landmark reading, no sighting either way), dead-reckoned with the calibrated odometry from
its TRUE pose where the stretch begins — the least error any filter or online smoother has
there, and what that stretch alone adds to the whole run's ATE.
"""

from __future__ import annotations

import argparse
from dataclasses import asdict, replace

import numpy as np
from scipy.optimize import minimize

from mrslam_core.datasets.mrclam import MrclamCalibration, MrclamDataset, OdometryIntegrator
from mrslam_core.evaluation.metrics import robust_sigma
from mrslam_core.experiments._output import write_tables
from mrslam_core.geometry.se2 import between, wrap_angle
from mrslam_core.pipelines.mrclam import MrclamConfig
from mrslam_core.slam.config import MotionConfig
from mrslam_core.slam.motion import predict_motion, reports_motion

#: readings further than this from the Vicon prediction are left out of the line fits [m], [rad]
#: (misread barcodes and occluded views; the noise fit models them as outliers instead)
GROSS_RANGE, GROSS_BEARING = 0.6, 0.1

MOTION_FIELDS = ("alpha1", "alpha2", "alpha3", "alpha4", "sigma_xy_rw", "sigma_theta_rw")


def huber_line(x: np.ndarray, y: np.ndarray, k: float = 1.345, iterations: int = 20) -> tuple[np.ndarray, float]:
    """Huber-weighted least squares y ≈ c0 + c1·x; returns ((c0, c1), robust σ of the residual)."""
    a = np.column_stack([np.ones_like(x), x])
    w = np.ones_like(y)
    for _ in range(iterations):
        c = np.linalg.lstsq(a * w[:, None], y * w, rcond=None)[0]
        r = y - a @ c
        s = robust_sigma(r)
        w = np.sqrt(np.minimum(1.0, k * s / np.maximum(np.abs(r), 1e-12)))
    return c, s


def contaminated_normal(e: np.ndarray, span: float, iterations: int = 200) -> tuple[float, float, float]:
    """EM fit of (1-ε)·N(μ, σ²) + ε·U(span) to residuals ``e``; returns (μ, σ, ε)."""
    mu = float(np.median(e))
    sigma = robust_sigma(e)
    eps = 0.05
    for _ in range(iterations):
        inlier = (1 - eps) * np.exp(-0.5 * ((e - mu) / sigma) ** 2) / (np.sqrt(2 * np.pi) * sigma)
        g = inlier / (inlier + eps / span)
        eps = 1.0 - float(g.mean())
        mu = float((g * e).sum() / g.sum())
        sigma = float(np.sqrt((g * (e - mu) ** 2).sum() / g.sum()))
    return mu, sigma, eps


def readings(ds: MrclamDataset, robot: int, robots: bool, span: tuple[float, float] | None = None
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A robot's landmark (or, with ``robots``, robot) readings and their Vicon truth, all of
    them or those in ``span`` = [start, end) [s].

    Returns:
        (reading (N,) [m], bearing read (N,) [rad], true distance (N,) [m], true bearing (N,) [rad]),
        from the robot's centre at the reading's time.
    """
    m = ds.robots[robot].measurements
    if span is not None:
        m = m[(m[:, 0] >= span[0]) & (m[:, 0] < span[1])]
    pose = ds.groundtruth(robot, m[:, 0])
    if robots:
        keep = m[:, 1] <= ds.num_robots
        target = np.empty((int(keep.sum()), 2))
        for s in np.unique(m[keep, 1]):  # each read robot at its readings' times
            mine = m[keep, 1] == s
            target[mine] = ds.groundtruth(int(s), m[keep][mine, 0])[:, :2]
    else:
        where = {int(s): (x, y) for s, x, y in ds.landmarks}
        keep = np.isin(m[:, 1], list(where))
        target = np.array([where[int(s)] for s in m[keep, 1]]).reshape(-1, 2)
    d = target - pose[keep, :2]
    r = np.hypot(d[:, 0], d[:, 1])
    b = wrap_angle(np.arctan2(d[:, 1], d[:, 0]) - pose[keep, 2])
    return m[keep, 2], m[keep, 3], r, b


def _plausible(reading: np.ndarray, bearing: np.ndarray, r: np.ndarray, b: np.ndarray) -> np.ndarray:
    return (np.abs(reading - r * np.cos(b)) < GROSS_RANGE) & (np.abs(wrap_angle(bearing - b)) < GROSS_BEARING)


def camera_line(rows: list[tuple]) -> tuple[np.ndarray, float]:
    """The reading-vs-depth line through :func:`readings` ``rows`` (one per robot, pooled),
    gross readings left out; returns ((offset [m], scale), robust residual σ [m])."""
    ok = [_plausible(*row) for row in rows]
    z = np.concatenate([(row[2] * np.cos(row[3]))[k] for row, k in zip(rows, ok)])
    y = np.concatenate([row[0][k] for row, k in zip(rows, ok)])
    return huber_line(z, y)


def bearing_offset(rows: list[tuple]) -> float:
    """Read minus true bearing [rad], the median over :func:`readings` ``rows`` (pooled), gross
    readings left out: the camera's yaw on the robot."""
    e = np.concatenate([wrap_angle(row[1] - row[3])[_plausible(*row)] for row in rows])
    return float(np.median(e))


def fit_range(data: dict[int, tuple]) -> tuple[tuple[float, float], dict[int, dict[str, float]]]:
    """The pooled reading-vs-depth line and, per robot, the residual σ under its own fit and
    under the fit of the other robots (leave one out).

    Args:
        data: robot -> :func:`readings` (landmarks).
    Returns:
        ((offset [m], scale), {robot: {"own": σ, "others": σ, "distance": σ of reading − r}}) [m].
    """
    def line(robots):
        return camera_line([data[i] for i in robots])

    (c0, c1), _ = line(list(data))
    per = {}
    for i, (reading, bearing, r, b) in data.items():
        k = _plausible(reading, bearing, r, b)
        own, s_own = line([i])
        others, _ = line([j for j in data if j != i])
        z = (r * np.cos(b))[k]
        per[i] = {"own": s_own, "others": robust_sigma(reading[k] - others[0] - others[1] * z),
                  "distance": robust_sigma(reading[k] - r[k]), "own_offset": float(own[0]),
                  "own_scale": float(own[1])}
    return (float(c0), float(c1)), per


def fit_velocity_scales(ds: MrclamDataset, delay: float, window: float = 1.0) -> tuple[float, float]:
    """Executed share of the commanded speed and turn rate: least squares over ``window`` [s]
    steps of all robots, Vicon path length and turn against the logged ones."""
    t0, t1 = ds.time_span()
    t = np.arange(t0 + window, t1 - window, window)
    dg, do, ag, ao = [], [], [], []
    for i, log in ds.robots.items():
        g = ds.groundtruth(i, t)
        o = OdometryIntegrator(log.odometry, delay).pose(t)
        dg.append(np.hypot(*np.diff(g[:, :2], axis=0).T))
        do.append(np.hypot(*np.diff(o[:, :2], axis=0).T))
        ag.append(wrap_angle(np.diff(g[:, 2])))
        ao.append(np.diff(o[:, 2]))
    dg, do, ag, ao = map(np.concatenate, (dg, do, ag, ao))
    return float(dg @ do / (do @ do)), float(ag @ ao / (ao @ ao))


def motion_windows(ds: MrclamDataset, delay: float, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Every robot's (calibrated) odometry and Vicon motion over consecutive ``step`` [s] windows.

    Returns:
        (odometry deltas (N, 3), Vicon deltas (N, 3)), each in the robot frame at the window's start.
    """
    t0, t1 = ds.time_span()
    t = np.arange(t0, t1, step)
    odo, true = [], []
    for i, log in ds.robots.items():
        g = ds.groundtruth(i, t)
        o = OdometryIntegrator(log.odometry, delay).pose(t)
        for poses, out in ((o, odo), (g, true)):
            d = between(poses[:-1], poses[1:])
            d[:, 2] = wrap_angle(poses[1:, 2] - poses[:-1, 2])
            out.append(d)
    return np.concatenate(odo), np.concatenate(true)


def fit_motion(odo: np.ndarray, true: np.ndarray, step: float, base: MotionConfig) -> tuple[MotionConfig, float]:
    """Maximum-likelihood :data:`MOTION_FIELDS` of ``base``: Vicon motion ~ N(odometry motion, P)
    with P the filter's linearised motion covariance (:func:`predict_motion`) over ``step`` [s].
    Windows whose error is gross (> 0.5 m or 0.5 rad: Vicon dropouts) are left out, and so are
    windows whose odometry reports no motion: the model adds no noise there (a zero-velocity
    update), whatever the parameters.

    Returns:
        (the fitted config, mean negative log-likelihood per window).
    """
    ok = (np.hypot(*(true - odo)[:, :2].T) < 0.5) & (np.abs(wrap_angle(true[:, 2] - odo[:, 2])) < 0.5)
    ok &= reports_motion(odo)
    odo, true = odo[ok], true[ok]
    zero = np.zeros((1, 3))

    def covariances(cfg: MotionConfig) -> np.ndarray:
        return np.array([predict_motion(zero, d, cfg, step)[1][0] for d in odo])

    # P is linear in (alpha1..4, sigma_xy_rw², sigma_theta_rw²): P = P0 + Σ p_k B_k, each basis
    # matrix from the filter's own predict_motion with one parameter at 1 and the others at 0
    none = replace(base, **dict.fromkeys(MOTION_FIELDS, 0.0))
    p0 = covariances(none)
    basis = np.stack([covariances(replace(none, **{n: 1.0})) - p0 for n in MOTION_FIELDS], axis=1)
    # the model's mean (the decomposed odometry motion) does not depend on the noise
    mean = np.array([predict_motion(zero, d, base, step)[0][0] for d in odo])
    err = true - mean
    err[:, 2] = wrap_angle(err[:, 2])

    def nll(logp: np.ndarray) -> float:
        cov = p0 + np.einsum("k,nkij->nij", np.exp(logp), basis)
        _, logdet = np.linalg.slogdet(cov)
        quad = np.einsum("ni,nij,nj->n", err, np.linalg.inv(cov), err)
        return float(np.mean(0.5 * (quad + logdet)))

    start = [getattr(base, n) ** (1 if n.startswith("alpha") else 2) for n in MOTION_FIELDS]
    res = minimize(nll, np.log(np.maximum(start, 1e-8)), method="Nelder-Mead",
                   options={"maxiter": 4000, "xatol": 1e-4, "fatol": 1e-8})
    p = np.exp(res.x)
    fitted = replace(base, **{n: float(v if n.startswith("alpha") else np.sqrt(v)) for n, v in zip(MOTION_FIELDS, p)})
    return fitted, float(res.fun)


def unmeasured_floor(ds: MrclamDataset, delay: float, step: float) -> dict[int, dict[str, float]]:
    """Per robot: its longest stretch [s] with no landmark reading, no sighting by it and none of
    it, and the RMS position error [m] there of dead reckoning (``ds``'s odometry, ``delay`` [s])
    from its Vicon pose where the stretch begins, on a ``step`` [s] grid; ``floor_m``: that
    error's share of an ATE over the whole run on the same grid (zero error elsewhere).

    Returns:
        robot -> {"from_s", "to_s" (from the run's start), "rms_m", "floor_m"}.
    """
    t0, t1 = ds.time_span()
    n_run = int(np.floor((t1 - t0) / step)) + 1
    out = {}
    for i, log in ds.robots.items():
        times = [log.measurements[:, 0]]
        times += [o.measurements[o.measurements[:, 1] == i, 0] for j, o in ds.robots.items() if j != i]
        t = np.unique(np.concatenate([[t0, t1], *times]))
        t = t[(t >= t0) & (t <= t1)]
        k = int(np.argmax(np.diff(t)))
        grid = np.arange(t[k], t[k + 1], step)
        truth = ds.groundtruth(i, grid)
        dead = OdometryIntegrator(log.odometry, delay).trajectory(truth[0], grid)
        e2 = ((dead[:, :2] - truth[:, :2]) ** 2).sum(axis=1)
        out[i] = {"from_s": float(t[k] - t0), "to_s": float(t[k + 1] - t0), "rms_m": float(np.sqrt(e2.mean())),
                  "floor_m": float(np.sqrt(e2.sum() / n_run))}
    return out


def calibrate(ds: MrclamDataset, cfg: MrclamConfig) -> dict:
    """Every fit of this module on one dataset (see the module docstring); plain numbers."""
    pooled, per_robot = fit_range({i: readings(ds, i, False) for i in ds.robots})
    v_scale, w_scale = fit_velocity_scales(ds, cfg.odometry_delay)
    cameras = sorted(per_robot)
    span = ds.time_span()  # where every robot's Vicon pose is measured, not held at an end
    for i in cameras:
        per_robot[i]["bearing_offset"] = bearing_offset([readings(ds, i, False, span)])
        per_robot[i]["sighting_bearing_offset"] = bearing_offset([readings(ds, i, True, span)])
    cal = MrclamCalibration(tuple(round(per_robot[i]["own_offset"], 3) for i in cameras),
                            tuple(round(per_robot[i]["own_scale"], 3) for i in cameras),
                            tuple(round(per_robot[i]["bearing_offset"], 4) for i in cameras), v_scale, w_scale)
    calibrated = ds.calibrated(cal)
    noise = {}
    for kind, robots in (("landmark", False), ("sighting", True)):
        rows = [readings(calibrated, i, robots) for i in ds.robots]
        er = np.concatenate([row[0] - row[2] for row in rows])
        eb = wrap_angle(np.concatenate([row[1] - row[3] for row in rows]))
        noise[kind] = {"range": contaminated_normal(er, 10.0), "bearing": contaminated_normal(eb, 2 * np.pi)}
    motion, nll = fit_motion(*motion_windows(calibrated, cfg.odometry_delay, cfg.team_step), cfg.team_step, cfg.filter.motion)
    return {"calibration": asdict(cal), "pooled_line": pooled, "per_robot": per_robot, "noise": noise,
            "motion": {n: getattr(motion, n) for n in MOTION_FIELDS}, "motion_nll": nll,
            "unmeasured": unmeasured_floor(calibrated, cfg.odometry_delay, cfg.team_step)}


def _yaml_number(key: str, value: float | tuple[float, ...]) -> str:
    digits = 4 if key == "bearing_offset" else 3  # radians need the fourth decimal
    if isinstance(value, tuple):
        return "[" + ", ".join(f"{x:.{digits}f}" for x in value) + "]"
    return f"{value:.{digits}f}"


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="mrslam experiment mrclam_calibration", description=__doc__)
    ap.add_argument("folder", help="MR.CLAM dataset folder, e.g. ../shared/data/mrclam/dataset6")
    ap.add_argument("--out", default="runs/experiments")
    args = ap.parse_args(argv)
    cfg = MrclamConfig()
    fit = calibrate(MrclamDataset(args.folder), cfg)
    cal, noise, motion = fit["calibration"], fit["noise"], fit["motion"]
    lines = [
        f"MR.CLAM {args.folder} against Vicon",
        "",
        f"camera reading = offset + scale · depth, each camera on its own line (all cameras pooled: "
        f"{fit['pooled_line'][0]:.3f} m + {fit['pooled_line'][1]:.3f} · depth); executed velocity "
        f"{cal['velocity_scale']:.3f} × commanded, turn rate {cal['turn_rate_scale']:.3f} × commanded, all robots pooled",
        "",
        "| robot | σ of reading − distance [m] | σ under the other robots' line [m] | σ under its own line [m] | own offset [m] | own scale | bearing offset, landmarks / robots [°] |",
        "|---|---|---|---|---|---|---|",
        *(f"| robot{i} | {p['distance']:.3f} | {p['others']:.3f} | {p['own']:.3f} | {p['own_offset']:+.3f} | {p['own_scale']:.3f} | "
          f"{np.degrees(p['bearing_offset']):+.2f} / {np.degrees(p['sighting_bearing_offset']):+.2f} |"
          for i, p in fit["per_robot"].items()),
        "",
        "| readings (calibrated) | range μ, σ [m], ε | bearing μ, σ [rad], ε |",
        "|---|---|---|",
        *(f"| {k} | {v['range'][0]:+.3f}, {v['range'][1]:.3f}, {v['range'][2]:.3f} | "
          f"{v['bearing'][0]:+.4f}, {v['bearing'][1]:.4f}, {v['bearing'][2]:.3f} |" for k, v in noise.items()),
        "",
        f"motion noise over {cfg.team_step} s windows (maximum likelihood, mean NLL {fit['motion_nll']:.3f}):",
        "",
        "```yaml",
        "calibration: {" + ", ".join(f"{k}: {_yaml_number(k, v)}" for k, v in cal.items()) + "}",
        f"sigma_range: {noise['landmark']['range'][1]:.3f}",
        f"sigma_bearing: {noise['landmark']['bearing'][1]:.4f}",
        f"sigma_sighting_range: {noise['sighting']['range'][1]:.3f}",
        f"sigma_sighting_bearing: {noise['sighting']['bearing'][1]:.4f}",
        "filter:",
        "  motion: {" + ", ".join(f"{k}: {v:.4g}" for k, v in motion.items()) + "}",
        "```",
        "",
        "Each robot's longest stretch without a measurement of or by it, dead-reckoned (calibrated) from its "
        "true pose where it begins: the least error a causal estimator has there.",
        "",
        "| robot | stretch [s] | RMS there [m] | its share of a whole-run ATE [m] |",
        "|---|---|---|---|",
        *(f"| robot{i} | {u['from_s']:.1f}–{u['to_s']:.1f} | {u['rms_m']:.3f} | {u['floor_m']:.3f} |"
          for i, u in fit["unmeasured"].items()),
    ]
    write_tables(args.out, "mrclam_calibration", "\n".join(lines), fit)
    return 0
