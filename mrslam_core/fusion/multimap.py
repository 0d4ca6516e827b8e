"""Globally consistent alignment of n > 2 maps (004 section 3.1).

Pairwise RANSAC transforms between maps that overlap need not be consistent: around a loop of
maps they should compose to the identity (004 eq. 2) and rarely do. Here the unknowns are the
poses X₁ … X_{n−1} of maps 1 … n−1 in map 0's frame (X₀ = identity), so every loop of the
relative transforms Xᵢ⁻¹Xⱼ composes to the identity by construction, and
``scipy.optimize.least_squares`` minimises, from the RANSAC estimates along a spanning tree:

- the landmark residuals of every accepted pair's inliers (004 eq. 3, E4…E_λ):
  (Xᵢ·pₐ − Xⱼ·p_b) / σ  for landmark a of map i matched to landmark b of map j;
- the deviation of each pairwise RANSAC transform Aᵢⱼ from the solution's Xᵢ⁻¹Xⱼ
  (the E1–E3 terms of 004, written as a prior per pair): (Aᵢⱼ⁻¹ Xᵢ⁻¹ Xⱼ) / (σ_xy, σ_xy, σ_θ).
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from mrslam_core.fusion.alignment import Alignment, apply_transform, ransac_align
from mrslam_core.fusion.config import FusionConfig
from mrslam_core.fusion.maps import FusionError, LandmarkMap
from mrslam_core.geometry.se2 import between, compose, inverse, wrap_angle


def compose_chain(transforms: Sequence[np.ndarray]) -> np.ndarray:
    """T₁ ⊕ T₂ ⊕ … ⊕ Tₙ of SE(2) transforms (3,) (004 eq. 2 wants the identity around a loop)."""
    out = np.zeros(3)
    for t in transforms:
        out = compose(out, np.asarray(t, float))
    return out


@dataclass(frozen=True)
class MultiMapAlignment:
    """Maps 0 … n−1 aligned into map 0's frame.

    Attributes:
        poses: (n, 3) pose of each map's frame in map 0's frame (x [m], y [m], θ [rad]); the
            transform that moves map i's points into map 0; NaN for maps not connected to map 0.
        initial: (n, 3) the same from the pairwise RANSAC transforms along a spanning tree.
        aligned: (n,) bool, map connected to map 0 by accepted pairwise alignments.
        pairwise: (i, j) with i < j → RANSAC alignment of map j (source) to map i (target).
        cost_initial, cost_final: ½Σr² of the least-squares problem at the start and the end.
    """

    poses: np.ndarray
    initial: np.ndarray
    aligned: np.ndarray
    pairwise: dict[tuple[int, int], Alignment]
    cost_initial: float
    cost_final: float

    def relative(self, i: int, j: int) -> np.ndarray:
        """(3,) transform moving map j's points into map i's frame (Xᵢ⁻¹Xⱼ)."""
        return between(self.poses[i], self.poses[j])

    def loop(self, cycle: Sequence[int]) -> np.ndarray:
        """Composition of the relative transforms around ``cycle`` (back to its start), (3,)."""
        c = list(cycle) + [cycle[0]]
        return compose_chain([self.relative(a, b) for a, b in itertools.pairwise(c)])


def _spanning_tree(n: int, edges: Mapping[tuple[int, int], Alignment]) -> np.ndarray:
    """Poses (n, 3) from the accepted edges, most inliers first (Prim from map 0); NaN if unreached."""
    poses = np.full((n, 3), np.nan)
    poses[0] = 0.0
    done = {0}
    while True:
        best = None
        for (i, j), a in edges.items():
            crosses = (i in done) != (j in done)
            if crosses and (best is None or a.inliers.size > best[2].inliers.size):
                best = (i, j, a)
        if best is None:
            return poses
        i, j, a = best
        if i in done:  # A_ij moves j into i: X_j = X_i ⊕ A_ij
            poses[j] = compose(poses[i], a.transform)
            done.add(j)
        else:
            poses[i] = compose(poses[j], inverse(a.transform))
            done.add(i)


def align_maps(
    maps: Sequence[LandmarkMap],
    config: FusionConfig,
    pairwise: Mapping[tuple[int, int], Alignment] | None = None,
) -> MultiMapAlignment:
    """Align every map into map 0's frame consistently (004 section 3.1).

    Args:
        maps: n landmark maps, each in its own frame.
        config: thresholds (RANSAC, loop and landmark sigmas).
        pairwise: precomputed alignments (i, j), i < j, of map j onto map i; missing pairs are
            computed with :func:`ransac_align`.
    """
    n = len(maps)
    if n < 2:
        raise FusionError("need at least two maps")
    pw: dict[tuple[int, int], Alignment] = dict(pairwise or {})
    for i in range(n):
        for j in range(i + 1, n):
            if (i, j) not in pw:
                pw[(i, j)] = ransac_align(maps[i], maps[j], config)
    edges = {k: a for k, a in pw.items() if a.accepted}
    initial = _spanning_tree(n, edges)
    aligned = np.isfinite(initial[:, 0])
    free = [k for k in range(1, n) if aligned[k]]
    col = {k: c for c, k in enumerate(free)}
    used = {k: a for k, a in edges.items() if aligned[k[0]] and aligned[k[1]]}

    # landmark terms, stacked once
    li, lj, pa, pb, sig = [], [], [], [], []
    for (i, j), a in used.items():
        pr = a.inlier_pairs
        li.append(np.full(len(pr), i))
        lj.append(np.full(len(pr), j))
        pa.append(maps[i].means[pr[:, 0], :2])
        pb.append(maps[j].means[pr[:, 1], :2])
        if config.landmark_sigma is not None:
            sig.append(np.full(len(pr), config.landmark_sigma))
        else:
            var = np.trace(maps[i].covs[pr[:, 0], :2, :2], axis1=1, axis2=2)
            var += np.trace(maps[j].covs[pr[:, 1], :2, :2], axis1=1, axis2=2)
            sig.append(np.sqrt(np.maximum(var / 2, 1e-12)))
    if used:
        li_a, lj_a = np.concatenate(li), np.concatenate(lj)
        pa_a, pb_a, sig_a = np.concatenate(pa), np.concatenate(pb), np.concatenate(sig)
    pair_keys = list(used)
    pair_t = np.array([used[k].transform for k in pair_keys]).reshape(-1, 3)
    pi = np.array([k[0] for k in pair_keys], np.int64)
    pj = np.array([k[1] for k in pair_keys], np.int64)
    scale = np.array([config.loop_sigma_xy, config.loop_sigma_xy, config.loop_sigma_theta])

    def unpack(x: np.ndarray) -> np.ndarray:
        poses = np.zeros((n, 3))
        for k, c in col.items():
            poses[k] = x[3 * c : 3 * c + 3]
        return poses

    def residuals(x: np.ndarray) -> np.ndarray:
        poses = unpack(x)
        out = []
        if used:
            a = apply_transform(poses[li_a], pa_a[:, None])[:, 0]  # each row its own map's pose
            b = apply_transform(poses[lj_a], pb_a[:, None])[:, 0]
            out.append(((a - b) / sig_a[:, None]).ravel())
            rel = between(poses[pi], poses[pj])
            dev = between(pair_t, rel)
            dev[:, 2] = np.sin(dev[:, 2])
            out.append((dev / scale).ravel())
        return np.concatenate(out) if out else np.zeros(0)

    if not free:
        return MultiMapAlignment(initial, initial, aligned, pw, 0.0, 0.0)
    x0 = np.concatenate([initial[k] for k in free])
    r0 = residuals(x0)
    sol = least_squares(residuals, x0, method="trf", x_scale="jac")
    poses = unpack(sol.x)
    poses[:, 2] = wrap_angle(poses[:, 2])
    poses[~aligned] = np.nan
    return MultiMapAlignment(poses, initial, aligned, pw, float(0.5 * r0 @ r0), float(sol.cost))
