"""Plots of a run: trajectories with ground truth and odometry, the map with covariance ellipses,
and position error over time. Headless (Agg backend)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import EllipseCollection  # noqa: E402

from mrslam_core.evaluation.metrics import position_errors  # noqa: E402


def ellipse_axes(cov: np.ndarray, nsigma: float = 2.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ``nsigma`` ellipses of the planar blocks of ``cov`` (L, d, d), d ≥ 2: full widths along
    the major axis, full heights along the minor axis (L,) [units of the covariance's square root]
    and the major axis' angle from x (L,) [deg]."""
    vals, vecs = np.linalg.eigh(np.asarray(cov, float)[:, :2, :2])
    vals = np.clip(vals, 0.0, None)
    angle = np.degrees(np.arctan2(vecs[:, 1, 1], vecs[:, 0, 1]))
    return 2 * nsigma * np.sqrt(vals[:, 1]), 2 * nsigma * np.sqrt(vals[:, 0]), angle


#: maps with more landmarks are drawn as a density, with the ellipses of the most uncertain only
MAX_ELLIPSES = 300


def plot_run(out: Path, trajectories: dict, landmarks: dict | None = None, truth_landmarks=None,
             occupancy: dict | None = None, corrections: dict | None = None) -> list[Path]:
    """Write trajectories.png, map.png, occupancy.png and errors.png into ``out``; returns their paths.

    Args:
        trajectories: robot -> {"t": (N,), "est": (N, 3), "gt": (N, 3) or None, "odom": (N, 3) or None}.
        landmarks: {"mean": (L, dim), "cov": (L, dim, dim)} of the best particle, or None.
        truth_landmarks: (T, 2) ground-truth landmark positions, or None.
        occupancy: the occupancy grid at the end, {"probability": (H, W) in [0, 1], "known": (H, W)
            bool, "origin": (x, y) [m] of cell (0, 0)'s corner, "resolution": [m/cell]}; row i is
            y = origin_y + (i + ½)·resolution.
        corrections: robot -> [(time [s], cause)] of its accepted pose corrections, marked on the
            error plot (:func:`mrslam_core.evaluation.report.corrections`).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    written = []

    fig, ax = plt.subplots(figsize=(9, 7))
    for i, (name, tr) in enumerate(sorted(trajectories.items())):
        c = colors[i % len(colors)]
        if tr.get("gt") is not None:
            ax.plot(tr["gt"][:, 0], tr["gt"][:, 1], "-", color=c, lw=1.0, alpha=0.5, label=f"{name} truth")
        if tr.get("odom") is not None:
            ax.plot(tr["odom"][:, 0], tr["odom"][:, 1], ":", color=c, lw=1.0, label=f"{name} odometry")
        ax.plot(tr["est"][:, 0], tr["est"][:, 1], "--", color=c, lw=1.4, label=f"{name} estimate")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(fontsize=7, ncol=2)
    ax.set_title("Trajectories (map frame)")
    fig.tight_layout()
    written.append(out / "trajectories.png")
    fig.savefig(written[-1], dpi=110)
    plt.close(fig)

    if landmarks is not None and len(landmarks["mean"]):
        written.append(_plot_map(out / "map.png", landmarks, truth_landmarks, trajectories, colors))

    if occupancy is not None:
        written.append(_plot_occupancy(out / "occupancy.png", occupancy, trajectories, colors))

    if any(tr.get("gt") is not None for tr in trajectories.values()):
        fig, ax = plt.subplots(figsize=(9, 4))
        for i, (name, tr) in enumerate(sorted(trajectories.items())):
            if tr.get("gt") is None:
                continue
            c = colors[i % len(colors)]
            t = tr["t"] - tr["t"][0]
            err = np.maximum(position_errors(tr["est"], tr["gt"]), 1e-3)
            ax.plot(t, err, "-", color=c, lw=1, label=f"{name} estimate")
            if tr.get("odom") is not None:
                ax.plot(t, np.maximum(position_errors(tr["odom"], tr["gt"]), 1e-3), ":", color=c, lw=1,
                        label=f"{name} odometry")
            events = (corrections or {}).get(name, [])
            if events and len(t):
                te = np.array([e for e, _ in events]) - tr["t"][0]
                causes = sorted({cause for _, cause in events})
                ax.plot(te, np.interp(te, t, err), "v", color=c, ms=7, mec="k", mew=0.5,
                        label=f"{name} corrected ({len(events)}: {', '.join(causes)})")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("position error [m]")
        # log scale: dead reckoning drifts metres while the estimate stays within centimetres
        ax.set_yscale("log")
        ax.set_ylim(bottom=1e-3)
        ax.grid(True, which="both", alpha=0.3)
        ax.set_title("Position error against ground truth (▼: pose corrections)")
        ax.legend(fontsize=7, ncol=2)
        fig.tight_layout()
        written.append(out / "errors.png")
        fig.savefig(written[-1], dpi=110)
        plt.close(fig)
    return written


def _plot_map(path: Path, landmarks: dict, truth_landmarks, trajectories: dict, colors: list) -> Path:
    """The best particle's landmarks with the robots' paths. Up to :data:`MAX_ELLIPSES` landmarks:
    each with its 2σ ellipse. More: their density (landmarks per cell, log scale) and the 2σ
    ellipses of the :data:`MAX_ELLIPSES` most uncertain only, where the map needs a look (at
    10⁴ landmarks every ellipse drawn hid the map under the others)."""
    mean = np.asarray(landmarks["mean"], float)
    widths, heights, angles = ellipse_axes(landmarks["cov"])
    fig, ax = plt.subplots(figsize=(9, 7))
    n = len(mean)
    if n <= MAX_ELLIPSES:
        shown = np.arange(n)
        ax.plot(mean[:, 0], mean[:, 1], "+", color="tab:blue", ms=4, label="landmarks (best particle)")
        title = f"Map: {n} landmarks, 2σ ellipses"
    else:
        lo, hi = mean[:, :2].min(axis=0), mean[:, :2].max(axis=0)
        cell = max(float((hi - lo).max()) / 200.0, 0.05)
        bins = np.maximum(np.ceil((hi - lo) / cell).astype(int), 1)
        counts, xe, ye = np.histogram2d(mean[:, 0], mean[:, 1], bins=bins, range=[[lo[0], hi[0]], [lo[1], hi[1]]])
        from matplotlib.colors import LogNorm

        img = ax.imshow(np.where(counts > 0, counts, np.nan).T, origin="lower", extent=(xe[0], xe[-1], ye[0], ye[-1]),
                        cmap="Blues", norm=LogNorm(vmin=1, vmax=max(counts.max(), 2)), interpolation="nearest")
        fig.colorbar(img, ax=ax, shrink=0.8, label=f"landmarks per {cell:.2f} m cell")
        shown = np.argsort(-widths)[:MAX_ELLIPSES]
        title = f"Map: {n} landmarks (density); 2σ ellipses of the {MAX_ELLIPSES} most uncertain"
    ax.add_collection(EllipseCollection(widths[shown], heights[shown], angles[shown], units="xy",
                                        offsets=mean[shown, :2], offset_transform=ax.transData, facecolors="none",
                                        edgecolors="tab:red" if n > MAX_ELLIPSES else "tab:blue", linewidths=0.6))
    if truth_landmarks is not None:
        ax.plot(truth_landmarks[:, 0], truth_landmarks[:, 1], "kx", ms=6, label="ground truth")
    for i, (name, tr) in enumerate(sorted(trajectories.items())):
        ax.plot(tr["est"][:, 0], tr["est"][:, 1], "-", color=colors[i % len(colors)], lw=0.8, alpha=0.7, label=name)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(fontsize=7)
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _plot_occupancy(path: Path, occupancy: dict, trajectories: dict, colors: list) -> Path:
    """The grid (white free, black occupied, grey unknown) with the estimated and true paths."""
    prob = np.asarray(occupancy["probability"], float)
    known = np.asarray(occupancy["known"], bool)
    res = float(occupancy["resolution"])
    ox, oy = np.asarray(occupancy["origin"], float)[:2]
    h, w = prob.shape
    fig, ax = plt.subplots(figsize=(9, 7))
    ax.imshow(np.where(known, 1.0 - prob, 0.5), origin="lower", cmap="gray", vmin=0.0, vmax=1.0,
              extent=(ox, ox + w * res, oy, oy + h * res), interpolation="nearest")
    for i, (name, tr) in enumerate(sorted(trajectories.items())):
        c = colors[i % len(colors)]
        if tr.get("gt") is not None:
            ax.plot(tr["gt"][:, 0], tr["gt"][:, 1], "-", color=c, lw=1.0, alpha=0.5, label=f"{name} truth")
        ax.plot(tr["est"][:, 0], tr["est"][:, 1], "--", color=c, lw=1.2, label=f"{name} estimate")
        ax.plot(*tr["est"][-1, :2], "o", color=c, ms=4)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(fontsize=7, ncol=2)
    ax.set_title(f"Occupancy grid: {known.mean():.0%} of the cells known")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
