"""Synthetic landmark maps with known frames, noise and wrong descriptor matches (tests and
``mrslam experiment fusion_synthetic``).

World landmarks get random positions and random unit descriptors. Map i sees some of them,
expressed in its own frame (whose pose in the world is known) with Gaussian position noise. A
share of a map's landmarks can have its descriptors swapped among themselves (a derangement), so
descriptor matching pairs them with the wrong landmark of the other map: outlier matches.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mrslam_core.fusion.maps import LandmarkMap
from mrslam_core.geometry.se2 import inverse, transform_points


@dataclass(frozen=True)
class SyntheticWorld:
    """Landmarks of the world frame: positions (N, 3) [m], descriptors (N, D) unit rows."""

    points: np.ndarray
    descriptors: np.ndarray


def make_world(
    rng: np.random.Generator, num: int, extent: tuple[float, float] = (20.0, 12.0),
    descriptor_dim: int = 32, planar: bool = False,
) -> SyntheticWorld:
    """``num`` landmarks uniform over [0, w] × [0, h] (z in 0.2–2.5 m, or 0 if planar)."""
    pts = np.column_stack([
        rng.uniform(0, extent[0], num), rng.uniform(0, extent[1], num),
        np.zeros(num) if planar else rng.uniform(0.2, 2.5, num),
    ])
    d = rng.standard_normal((num, descriptor_dim))
    return SyntheticWorld(pts, (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32))


def observe_map(
    rng: np.random.Generator, world: SyntheticWorld, rows: np.ndarray, frame: np.ndarray,
    noise: float = 0.05, descriptor_noise: float = 0.02, swap: np.ndarray | None = None,
) -> LandmarkMap:
    """The map of world landmarks ``rows`` in the frame whose world pose is ``frame`` (3,).

    Args:
        noise: σ of each position coordinate [m]; covariances are diag(σ²).
        descriptor_noise: σ of the Gaussian added to each descriptor component.
        swap: positions (into ``rows``) whose descriptors are cyclically exchanged: outliers.

    Returns:
        a map with ``ids`` = the world rows (the ground-truth correspondence).
    """
    rows = np.asarray(rows, np.int64)
    pts = transform_points(inverse(np.asarray(frame, float)), world.points[rows])
    pts = pts + rng.normal(0.0, noise, pts.shape)
    desc = world.descriptors[rows] + rng.normal(0.0, descriptor_noise, (rows.size, world.descriptors.shape[1]))
    if swap is not None and len(swap) > 1:
        swap = np.asarray(swap, np.int64)
        desc[swap] = desc[np.roll(swap, 1)]
    covs = np.broadcast_to(np.eye(3) * noise**2, (rows.size, 3, 3)).copy()
    return LandmarkMap(pts, covs, desc.astype(np.float32), np.ones(rows.size, np.int64), rows)


@dataclass(frozen=True)
class MapPair:
    """Two overlapping maps and the truth.

    Attributes:
        target, source: the maps (``ids`` = world rows).
        transform: (3,) true source → target transform.
        common: world rows seen by both.
        outliers: world rows of common landmarks whose source descriptor points elsewhere.
    """

    target: LandmarkMap
    source: LandmarkMap
    transform: np.ndarray
    common: np.ndarray
    outliers: np.ndarray


def make_map_pair(
    rng: np.random.Generator,
    transform: np.ndarray,
    num_landmarks: int = 60,
    overlap: float = 0.6,
    outlier_fraction: float = 0.0,
    noise: float = 0.05,
    descriptor_dim: int = 32,
    planar: bool = False,
) -> MapPair:
    """Target and source maps of ``num_landmarks`` each, sharing ``overlap`` of them.

    The target's frame is the world; the source's frame has world pose ``transform`` (so
    ``transform`` moves source points into the target). ``outlier_fraction`` of the shared
    landmarks get swapped descriptors in the source map, so that share of the descriptor matches
    is wrong.
    """
    n_common = round(overlap * num_landmarks)
    world = make_world(rng, 2 * num_landmarks - n_common, descriptor_dim=descriptor_dim, planar=planar)
    perm = rng.permutation(len(world.points))
    common = perm[:n_common]
    t_rows = rng.permutation(np.concatenate([common, perm[n_common:num_landmarks]]))
    s_rows = rng.permutation(np.concatenate([common, perm[num_landmarks:]]))
    n_out = round(outlier_fraction * n_common)
    shared_pos = np.flatnonzero(np.isin(s_rows, common))
    swap = rng.choice(shared_pos, n_out, replace=False) if n_out > 1 else None
    tgt = observe_map(rng, world, t_rows, np.zeros(3), noise)
    src = observe_map(rng, world, s_rows, np.asarray(transform, float), noise, swap=swap)
    out = s_rows[swap] if swap is not None else np.zeros(0, np.int64)
    return MapPair(tgt, src, np.asarray(transform, float), common, out)
