"""The occupancy grid as a ROS map file: a PGM image and a YAML of the nav2 ``map_server`` format.

The YAML holds ``image`` (the PGM's file name), ``mode: trinary``, ``resolution`` [m/cell],
``origin`` [x, y, yaw] [m, rad] of the lower-left pixel's corner, ``negate: 0``,
``occupied_thresh`` and ``free_thresh``. As ``map_saver`` writes them, free cells are 254,
occupied ones 0 and unknown ones 205; the first image row is the grid's top (largest y).
``nav2_map_server`` and ``map_server`` load the pair as it is.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

FREE, OCCUPIED, UNKNOWN = 254, 0, 205


def save_map_file(path: str | Path, probability: np.ndarray, known: np.ndarray, origin: np.ndarray,
                  resolution: float, free_thresh: float = 0.25, occupied_thresh: float = 0.65) -> Path:
    """Write ``path`` (.yaml) and the PGM beside it (same stem); returns the YAML's path.

    Args:
        probability: (H, W) occupancy probability in [0, 1]; row i is y = origin_y + (i + ½)·resolution.
        known: (H, W) bool, cells observed at least once.
        origin: (x, y) or (x, y, yaw) of cell (0, 0)'s lower-left corner [m, rad].
        resolution: cell side [m].
        free_thresh, occupied_thresh: cells below / above these probabilities are free / occupied;
            the rest of the known cells are written as unknown, as ``map_saver`` does.
    """
    path = Path(path).with_suffix(".yaml")
    prob = np.asarray(probability, float)
    known = np.asarray(known, bool)
    if prob.ndim != 2 or prob.shape != known.shape:
        raise ValueError(f"probability {prob.shape} and known {known.shape} must be the same (H, W)")
    if not resolution > 0:
        raise ValueError(f"resolution {resolution} must be > 0")
    pixels = np.full(prob.shape, UNKNOWN, np.uint8)
    pixels[known & (prob < free_thresh)] = FREE
    pixels[known & (prob > occupied_thresh)] = OCCUPIED
    h, w = pixels.shape
    pgm = path.with_suffix(".pgm")
    path.parent.mkdir(parents=True, exist_ok=True)
    pgm.write_bytes(f"P5\n{w} {h}\n255\n".encode() + np.flipud(pixels).tobytes())
    o = np.zeros(3)
    o[: len(origin)] = np.asarray(origin, float)[:3]
    meta = {"image": pgm.name, "mode": "trinary", "resolution": float(resolution),
            "origin": [float(v) for v in o], "negate": 0,
            "occupied_thresh": float(occupied_thresh), "free_thresh": float(free_thresh)}
    path.write_text(yaml.safe_dump(meta, sort_keys=False))
    return path


def load_map_file(path: str | Path) -> tuple[np.ndarray, dict]:
    """Read a map YAML and its PGM -> (pixels (H, W) uint8 with row i at y = origin_y + (i + ½)·res,
    the YAML's entries)."""
    path = Path(path)
    meta = yaml.safe_load(path.read_text())
    data = (path.parent / meta["image"]).read_bytes()
    fields = data.split(maxsplit=4)
    if fields[0] != b"P5" or int(fields[3]) != 255:
        raise ValueError(f"{meta['image']}: not an 8-bit binary PGM")
    w, h = int(fields[1]), int(fields[2])
    pixels = np.frombuffer(data[len(data) - w * h:], np.uint8).reshape(h, w)
    return np.flipud(pixels).copy(), meta
