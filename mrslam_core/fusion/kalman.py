"""Fusion of two aligned landmark maps with the stationary Kalman step (004 section 4).

For each matched pair (landmark 1 of the target map, landmark 2 of the source map moved into the
target frame, p' = R·p + t with Σ' = R·Σ·Rᵀ):

    K  = Σ1 (Σ1 + Σ2)⁻¹            (eq. 4)
    C  = C1 + K (C2 − C1)          (eq. 5, corrected: the paper prints C1 − C2)
    Σ  = (I − K) Σ1                (eq. 6)

The fused descriptor is the count-weighted mean of the two; unmatched landmarks of both maps are
carried over unchanged (the source's moved into the target frame).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mrslam_core.fusion.maps import FusionError, LandmarkMap


def kalman_fuse(
    c1: np.ndarray, s1: np.ndarray, c2: np.ndarray, s2: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Stationary Kalman fusion of two estimates of the same points, eqs. 4–6 (corrected).

    Args:
        c1, c2: (..., d) positions [m], both in the same frame.
        s1, s2: (..., d, d) their covariances [m²].

    Returns:
        (fused positions (..., d), fused covariances (..., d, d), symmetrised).
    """
    c1 = np.asarray(c1, float)
    c2 = np.asarray(c2, float)
    s1 = np.asarray(s1, float)
    s2 = np.asarray(s2, float)
    # K = Σ1 S⁻¹ with S symmetric: solve S Kᵀ = Σ1ᵀ = Σ1
    k = np.swapaxes(np.linalg.solve(s1 + s2, s1), -1, -2)
    c = c1 + (k @ (c2 - c1)[..., None])[..., 0]
    eye = np.eye(c1.shape[-1])
    s = (eye - k) @ s1
    return c, 0.5 * (s + np.swapaxes(s, -1, -2))


@dataclass(frozen=True)
class FusedMap:
    """Two maps fused into the target's frame.

    Attributes:
        map: the fused map: target landmarks first (in the target's order, matched ones
            fused), then the source's carried-over landmarks.
        target_rows: (Nt,) row in ``map`` of each target landmark.
        source_rows: (Ns,) row in ``map`` of each source landmark (-1: dropped).
        fused: (F, 2) (target row, source row) pairs that were fused.
    """

    map: LandmarkMap
    target_rows: np.ndarray
    source_rows: np.ndarray
    fused: np.ndarray


def fuse_maps(
    target: LandmarkMap,
    source: LandmarkMap,
    transform: np.ndarray,
    pairs: np.ndarray,
    drop_source: np.ndarray | None = None,
) -> FusedMap:
    """Fuse ``source`` into ``target`` given the source → target transform and matched pairs.

    Args:
        target: map 1, defines the frame of the result.
        source: map 2, in its own frame.
        transform: (3,) source → target (tx [m], ty [m], θ [rad]).
        pairs: (F, 2) (target row, source row) of the landmarks to fuse (the inliers); each row
            of either map at most once.
        drop_source: source rows to leave out of the result (e.g. outlier matches of
            identifying descriptors).
    """
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    if np.unique(pairs[:, 0]).size != len(pairs) or np.unique(pairs[:, 1]).size != len(pairs):
        raise FusionError("each landmark may be fused at most once")
    moved = source.transformed(transform)
    t, s = pairs[:, 0], pairs[:, 1]
    means = target.means.copy()
    covs = target.covs.copy()
    desc = target.descriptors.astype(np.float64)
    counts = target.counts.copy()
    if len(pairs):
        means[t], covs[t] = kalman_fuse(target.means[t], target.covs[t], moved.means[s], moved.covs[s])
        if desc.shape[1] != moved.descriptors.shape[1]:
            raise FusionError("descriptor lengths differ between the maps")
        n1 = target.counts[t].astype(float)[:, None]
        n2 = moved.counts[s].astype(float)[:, None]
        desc[t] = (n1 * target.descriptors[t] + n2 * moved.descriptors[s]) / np.maximum(n1 + n2, 1e-12)
        counts[t] = target.counts[t] + moved.counts[s]
    carry = np.ones(len(source), bool)
    carry[s] = False
    if drop_source is not None:
        carry[np.asarray(drop_source, np.int64)] = False
    rows = np.flatnonzero(carry)
    source_rows = np.full(len(source), -1, np.int64)
    source_rows[s] = t
    source_rows[rows] = len(target) + np.arange(rows.size)
    fused = LandmarkMap(
        np.concatenate([means, moved.means[rows]]),
        np.concatenate([covs, moved.covs[rows]]),
        np.concatenate([desc, moved.descriptors[rows]]).astype(np.float32),
        np.concatenate([counts, moved.counts[rows]]),
        np.concatenate([target.ids, np.full(rows.size, -1, np.int64)]),
    )
    return FusedMap(fused, np.arange(len(target)), source_rows, pairs)
