"""A landmark map as plain arrays, and its rigid motion between frames."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from mrslam_core.slam.filter import MultiRobotFastSLAM


class FusionError(ValueError):
    """Maps or transforms that the alignment and fusion code cannot use (shapes, NaNs)."""


def rotation3(theta: float) -> np.ndarray:
    """(3, 3) rotation by θ [rad] about z (004 eq. 8)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class LandmarkMap:
    """N landmarks of one map, in that map's frame.

    Attributes:
        means: (N, 3) positions [m] in the map's frame (z = 0 for planar maps).
        covs: (N, 3, 3) position covariances [m²].
        descriptors: (N, D) float32 appearance descriptors (D may be 0).
        counts: (N,) int64 observations that went into each landmark (weights when descriptors
            are averaged).
        ids: (N,) int64 identifiers in the source (the filter's slot indices; -1 unknown).
    """

    means: np.ndarray
    covs: np.ndarray
    descriptors: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), np.float32))
    counts: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    def __post_init__(self) -> None:
        means = np.asarray(self.means, float)
        if means.ndim != 2 or means.shape[1] != 3:
            raise FusionError(f"means must be (N, 3), got {means.shape}")
        n = means.shape[0]
        covs = np.asarray(self.covs, float)
        if covs.shape != (n, 3, 3):
            raise FusionError(f"covs must be {(n, 3, 3)}, got {covs.shape}")
        desc = np.asarray(self.descriptors, np.float32)
        if desc.size == 0:
            desc = np.zeros((n, desc.shape[1] if desc.ndim == 2 and desc.shape[0] == n else 0), np.float32)
        if desc.ndim != 2 or desc.shape[0] != n:
            raise FusionError(f"descriptors must be (N={n}, D), got {desc.shape}")
        counts = np.asarray(self.counts, np.int64)
        if counts.size == 0:
            counts = np.ones(n, np.int64)
        ids = np.asarray(self.ids, np.int64)
        if ids.size == 0:
            ids = np.full(n, -1, np.int64)
        if counts.shape != (n,) or ids.shape != (n,):
            raise FusionError(f"counts and ids must be ({n},), got {counts.shape}, {ids.shape}")
        if not (np.isfinite(means).all() and np.isfinite(covs).all()):
            raise FusionError("means and covs must be finite")
        for name, value in (("means", means), ("covs", covs), ("descriptors", desc), ("counts", counts), ("ids", ids)):
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return self.means.shape[0]

    @classmethod
    def from_arrays(
        cls,
        means: np.ndarray,
        covs: np.ndarray,
        descriptors: np.ndarray | None = None,
        counts: np.ndarray | None = None,
        ids: np.ndarray | None = None,
        z_variance: float = 1.0,
    ) -> LandmarkMap:
        """A map from planar (N, 2) / (N, 2, 2) or spatial (N, 3) / (N, 3, 3) arrays.

        Planar landmarks get z = 0 and var(z) = ``z_variance`` [m²], uncorrelated with x, y (so
        the planar part of any fusion is unaffected by it).
        """
        means = np.asarray(means, float)
        covs = np.asarray(covs, float)
        n = means.shape[0]
        if means.ndim == 2 and means.shape[1] == 2:
            if covs.shape != (n, 2, 2):
                raise FusionError(f"planar covs must be {(n, 2, 2)}, got {covs.shape}")
            means = np.column_stack([means, np.zeros(n)])
            c3 = np.zeros((n, 3, 3))
            c3[:, :2, :2] = covs
            c3[:, 2, 2] = z_variance
            covs = c3
        empty = np.zeros(0, np.int64)
        return cls(
            means, covs,
            np.zeros((n, 0), np.float32) if descriptors is None else descriptors,
            empty if counts is None else counts,
            empty if ids is None else ids,
        )

    @classmethod
    def from_filter(
        cls, slam: MultiRobotFastSLAM, particle: int | None = None, z_variance: float = 1.0
    ) -> LandmarkMap:
        """The map of one particle of a filter (default: the best particle, 000 eq. 14).

        ``ids`` are the filter's slot indices; planar (range-bearing) maps are padded to 3D.
        """
        m = slam.best_particle() if particle is None else int(particle)
        slots, mean, cov, desc = slam.landmarks.particle_map(m)
        (count,) = slam.landmarks.gather(np.full(slots.size, m), slots, ("count",))
        return cls.from_arrays(mean, cov, desc, count, slots, z_variance)

    def subset(self, rows: np.ndarray) -> LandmarkMap:
        """The landmarks at ``rows`` (index or boolean array), same frame."""
        return LandmarkMap(self.means[rows], self.covs[rows], self.descriptors[rows], self.counts[rows], self.ids[rows])

    def transformed(self, transform: np.ndarray) -> LandmarkMap:
        """This map moved into another frame by ``transform`` (tx, ty, θ): p' = R·p + t,
        Σ' = R·Σ·Rᵀ (004 eq. 7 with the convention of this rotation; the paper prints RᵀΣR,
        which is the inverse motion)."""
        t = np.asarray(transform, float)
        if t.shape != (3,) or not np.isfinite(t).all():
            raise FusionError(f"transform must be finite (3,), got {t}")
        r = rotation3(t[2])
        means = self.means @ r.T + np.array([t[0], t[1], 0.0])
        covs = r @ self.covs @ r.T
        return LandmarkMap(means, covs, self.descriptors, self.counts, self.ids)
