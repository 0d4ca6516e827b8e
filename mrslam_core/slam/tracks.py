"""Per-particle memory of which landmark each frontend track of a robot was associated with.

A frontend track is one physical point followed through consecutive images by appearance; it
stays the same point when an odometry step is off by 3σ, where projecting the map through the
predicted pose no longer finds it. :class:`TrackMemory` keeps, for one robot, the slot each of
its recent track ids was associated with (or created) in every particle, so the filter can
associate a continuing track with its landmark again (``AssociationConfig.track_gate``).
"""

from __future__ import annotations

import numpy as np


class TrackMemory:
    """Track id -> landmark slot in each particle, for the tracks of the last ``memory`` sets.

    Attributes:
        ids: (T,) int64 track ids remembered.
        slots: (M, T) int64 slot of each track in each particle, −1 where none.
        last: (T,) int64 the set counter when each track was last seen.
        sets: sets recorded so far.
    """

    def __init__(self, num_particles: int, memory: int):
        self.memory = int(memory)
        self.ids = np.zeros(0, np.int64)
        self.slots = np.zeros((num_particles, 0), np.int64)
        self.last = np.zeros(0, np.int64)
        self.sets = 0

    def lookup(self, tracks: np.ndarray) -> np.ndarray:
        """(M, B) slot of each of ``tracks`` (B,) in each particle, −1 for unknown tracks."""
        m = self.slots.shape[0]
        out = np.full((m, tracks.shape[0]), -1, np.int64)
        if self.ids.size == 0 or tracks.size == 0:
            return out
        pos = np.searchsorted(self.ids, tracks)
        pos = np.minimum(pos, self.ids.size - 1)
        hit = (self.ids[pos] == tracks) & (tracks >= 0)
        out[:, hit] = self.slots[:, pos[hit]]
        return out

    def record(self, tracks: np.ndarray, slots: np.ndarray) -> None:
        """Remember ``slots`` (M, B) for ``tracks`` (B,) (−1 ids are ignored; a −1 slot keeps the
        particle's previous entry), then forget tracks unseen for ``memory`` sets."""
        self.sets += 1
        tracks, first = np.unique(tracks, return_index=True)  # a track id twice in a set: its first
        slots = slots[:, first]
        known = tracks >= 0
        tracks, slots = tracks[known], slots[:, known]
        old = self.lookup(tracks)
        slots = np.where(slots >= 0, slots, old)
        keep = (self.last > self.sets - self.memory) & ~np.isin(self.ids, tracks)
        ids = np.concatenate([self.ids[keep], tracks])
        order = np.argsort(ids, kind="stable")
        self.ids = ids[order]
        self.slots = np.concatenate([self.slots[:, keep], slots], axis=1)[:, order]
        self.last = np.concatenate([self.last[keep], np.full(tracks.size, self.sets)])[order]

    def copy_rows(self, dst: np.ndarray, src: np.ndarray) -> None:
        """Particles ``dst`` take the memory of particles ``src`` (resampling)."""
        self.slots[dst] = self.slots[src]

    def remap(self, remap: np.ndarray) -> None:
        """Slots renumbered by the landmark store's compaction: ``remap`` old -> new (−1: dropped)."""
        ok = self.slots >= 0
        self.slots[ok] = remap[self.slots[ok]]

    def clear(self) -> None:
        """Forget every track (the robot restarted or was re-placed)."""
        self.ids = self.ids[:0]
        self.slots = self.slots[:, :0]
        self.last = self.last[:0]
