"""The best particle's landmark map as a file: ``mrslam map export`` and ``mrslam map load``.

``export RUN_OR_CHECKPOINT --out FILE`` reads a filter checkpoint (or the newest one in a run
folder), takes the landmarks of the best particle (eq. 14) and writes them as

- ``.npz``: arrays ``slots`` (N,) int64, ``mean`` (N, dim) float64 [m, map frame], ``cov``
  (N, dim, dim) float64 [m²], ``descriptor`` (N, D) float32, ``count`` (N,) int32, and
  ``header`` (UTF-8 JSON as uint8: format, version, source, robots, dim, model, frame);
  readable with ``np.load(..., allow_pickle=False)``;
- ``.ply``: binary little-endian PLY, one vertex per landmark with float64 x y z (z = 0 for planar
  landmarks), int32 slot and count, the upper covariance terms (cxx cxy cxz cyy cyz czz, or cxx
  cxy cyy for dim 2) and the descriptor as float32 d0…d{D-1} (CloudCompare, Open3D, MeshLab);
- ``.csv``: a header line and one row per landmark with the same columns as the PLY.

``load FILE`` reads any of these (or a checkpoint) and prints a summary.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mrslam_core.errors import InputError

MAP_FORMAT = "mrslam-landmark-map"
MAP_VERSION = 1
FORMATS = (".npz", ".ply", ".csv")


class MapFileError(InputError, ValueError):
    """A map or checkpoint file that cannot be read or written."""


@dataclass(frozen=True)
class LandmarkMap:
    """Landmarks of one particle.

    Attributes:
        slots: (N,) int64 slot index of each landmark in the filter's store.
        mean: (N, dim) positions in the map frame [m] (dim 3: x y z; dim 2: x y).
        cov: (N, dim, dim) covariances [m²].
        descriptor: (N, D) float32 appearance descriptors (D may be 0).
        count: (N,) int32 observations associated with each landmark (creation included).
        meta: source file, robots, model name, frame.
    """

    slots: np.ndarray
    mean: np.ndarray
    cov: np.ndarray
    descriptor: np.ndarray
    count: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = self.slots.shape[0]
        dim = self.mean.shape[1] if self.mean.ndim == 2 else -1
        if dim not in (2, 3) or self.mean.shape[0] != n:
            raise MapFileError(f"mean must be (N={n}, 2 or 3), got {self.mean.shape}")
        if self.cov.shape != (n, dim, dim):
            raise MapFileError(f"cov must be {(n, dim, dim)}, got {self.cov.shape}")
        if self.descriptor.ndim != 2 or self.descriptor.shape[0] != n or self.count.shape != (n,):
            raise MapFileError("descriptor must be (N, D) and count (N,)")

    @property
    def dim(self) -> int:
        return int(self.mean.shape[1])

    def __len__(self) -> int:
        return int(self.slots.shape[0])


# ----------------------------------------------------------------------------- sources
def _find_checkpoint(folder: Path) -> Path:
    """The newest filter checkpoint under ``folder``: any file (whatever its suffix) that is an
    .npz archive whose header says it is one."""
    from mrslam_core.slam.checkpoint import CheckpointError, read_header

    found = []
    for p in folder.rglob("*"):
        try:
            if not p.is_file() or p.name.startswith("."):  # .NAME.tmp: a checkpoint being written
                continue
            with p.open("rb") as fh:
                if fh.read(4) != b"PK\x03\x04":  # not a zip archive
                    continue
            read_header(p)
        except (OSError, CheckpointError):
            continue
        found.append(p)
    if not found:
        raise MapFileError(f"{folder}: no filter checkpoint found")
    return max(found, key=lambda p: p.stat().st_mtime)


def map_from_checkpoint(path: str | Path) -> LandmarkMap:
    """The best particle's landmarks of a filter checkpoint (or of the newest in a run folder)."""
    from mrslam_core.slam.checkpoint import CheckpointError, load_checkpoint

    path = Path(path)
    if path.is_dir():
        path = _find_checkpoint(path)
    try:
        slam, _ = load_checkpoint(path)
    except CheckpointError as exc:
        raise MapFileError(str(exc)) from exc
    slots, mean, cov, desc, count = slam.best_map()
    meta = {"source": str(path), "robots": list(slam.robots), "model": slam.model.name,
            "best_particle": slam.best_particle(), "frame": "map", "steps": slam.steps}
    return LandmarkMap(slots.astype(np.int64), mean.astype(float), cov.astype(float),
                       desc.astype(np.float32), count.astype(np.int32), meta)


# ----------------------------------------------------------------------------- columns (ply, csv)
def _columns(dim: int, d: int) -> list[str]:
    cov = ["cxx", "cxy", "cxz", "cyy", "cyz", "czz"] if dim == 3 else ["cxx", "cxy", "cyy"]
    return ["x", "y", "z", "slot", "count"] + cov + [f"d{i}" for i in range(d)]


def _record_dtype(dim: int, d: int) -> np.dtype:
    names = _columns(dim, d)
    types = ["<f8"] * 3 + ["<i4", "<i4"] + ["<f8"] * (len(names) - 5 - d) + ["<f4"] * d
    return np.dtype(list(zip(names, types)))


def _records(lmap: LandmarkMap) -> np.ndarray:
    n, dim, d = len(lmap), lmap.dim, lmap.descriptor.shape[1]
    rec = np.zeros(n, _record_dtype(dim, d))
    for i, axis in enumerate("xyz"[:dim]):
        rec[axis] = lmap.mean[:, i]
    rec["slot"], rec["count"] = lmap.slots, lmap.count
    iu = np.triu_indices(dim)
    for name, (i, j) in zip(_columns(dim, d)[5 : 5 + len(iu[0])], zip(*iu)):
        rec[name] = lmap.cov[:, i, j]
    for i in range(d):
        rec[f"d{i}"] = lmap.descriptor[:, i]
    return rec


def _from_records(rec: np.ndarray, dim: int, meta: dict[str, Any]) -> LandmarkMap:
    n = rec.shape[0]
    d = sum(1 for name in rec.dtype.names if name[0] == "d" and name[1:].isdigit())
    mean = np.column_stack([rec[a].astype(float) for a in "xyz"[:dim]]).reshape(n, dim)
    cov = np.zeros((n, dim, dim))
    iu = np.triu_indices(dim)
    for name, (i, j) in zip(_columns(dim, d)[5 : 5 + len(iu[0])], zip(*iu)):
        cov[:, i, j] = cov[:, j, i] = rec[name]
    desc = np.column_stack([rec[f"d{i}"] for i in range(d)]).astype(np.float32) if d else np.zeros((n, 0), np.float32)
    return LandmarkMap(rec["slot"].astype(np.int64), mean, cov, desc.reshape(n, d),
                       rec["count"].astype(np.int32), meta)


# ----------------------------------------------------------------------------- writers
def _atomic_write(path: Path, write) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def save_map(lmap: LandmarkMap, path: str | Path) -> Path:
    """Write ``lmap`` as .npz, .ply or .csv (by the suffix of ``path``), atomically."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in FORMATS:
        raise MapFileError(f"{path}: unknown map format {suffix!r}; use one of {FORMATS}")
    meta = {"format": MAP_FORMAT, "version": MAP_VERSION, "dim": lmap.dim, **lmap.meta}
    if suffix == ".npz":
        header = np.frombuffer(json.dumps(meta).encode("utf-8"), np.uint8)
        _atomic_write(path, lambda fh: np.savez(
            fh, header=header, slots=lmap.slots, mean=lmap.mean, cov=lmap.cov,
            descriptor=lmap.descriptor, count=lmap.count))
    elif suffix == ".ply":
        rec = _records(lmap)
        ply_type = {"<f8": "double", "<f4": "float", "<i4": "int"}
        lines = ["ply", "format binary_little_endian 1.0",
                 f"comment {MAP_FORMAT} {json.dumps(meta)}", f"element vertex {len(rec)}"]
        lines += [f"property {ply_type[rec.dtype[name].str]} {name}" for name in rec.dtype.names]
        lines.append("end_header")
        head = ("\n".join(lines) + "\n").encode("utf-8")
        _atomic_write(path, lambda fh: (fh.write(head), fh.write(rec.tobytes())))
    else:
        rec = _records(lmap)
        cols = rec.dtype.names
        fmt = {"<f8": "%.17g", "<f4": "%.9g", "<i4": "%d"}
        table = np.column_stack([rec[c].astype(float) for c in cols]) if len(rec) else np.zeros((0, len(cols)))
        head = f"# {MAP_FORMAT} {json.dumps(meta)}\n" + ",".join(cols)

        def write(fh) -> None:
            np.savetxt(fh, table, delimiter=",", header=head, comments="",
                       fmt=[fmt[rec.dtype[c].str] for c in cols])

        _atomic_write(path, write)
    return path


# ----------------------------------------------------------------------------- readers
def _header_meta(text: str, path: Path) -> dict[str, Any]:
    try:
        meta = json.loads(text)
    except ValueError as exc:
        raise MapFileError(f"{path}: map header is not JSON: {exc}") from exc
    if not isinstance(meta, dict) or meta.get("format") != MAP_FORMAT:
        raise MapFileError(f"{path}: not an mrslam landmark map")
    if meta.get("version") != MAP_VERSION:
        raise MapFileError(f"{path}: map version {meta.get('version')!r}, this mrslam reads {MAP_VERSION}")
    return meta


def _load_npz(path: Path) -> LandmarkMap:
    try:
        with np.load(path, allow_pickle=False) as data:
            if "header" in data.files and "filter.poses" in data.files:
                return map_from_checkpoint(path)
            arrays = {k: data[k] for k in ("header", "slots", "mean", "cov", "descriptor", "count")}
    except KeyError as exc:
        raise MapFileError(f"{path}: map lacks {exc}") from exc
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        if isinstance(exc, MapFileError):
            raise
        raise MapFileError(f"{path}: not a readable .npz: {exc}") from exc
    meta = _header_meta(arrays["header"].tobytes().decode("utf-8", "replace"), path)
    return LandmarkMap(arrays["slots"].astype(np.int64), arrays["mean"].astype(float),
                       arrays["cov"].astype(float), arrays["descriptor"].astype(np.float32),
                       arrays["count"].astype(np.int32), meta)


def _load_ply(path: Path) -> LandmarkMap:
    raw = path.read_bytes()
    end = raw.find(b"end_header\n")
    if not raw.startswith(b"ply\n") or end < 0:
        raise MapFileError(f"{path}: not a PLY file")
    lines = raw[:end].decode("utf-8", "replace").splitlines()
    if "format binary_little_endian 1.0" not in lines:
        raise MapFileError(f"{path}: only binary little-endian PLY maps written by mrslam are read")
    meta_line = next((ln for ln in lines if ln.startswith(f"comment {MAP_FORMAT} ")), None)
    if meta_line is None:
        raise MapFileError(f"{path}: a PLY file, but not an mrslam landmark map")
    meta = _header_meta(meta_line[len(f"comment {MAP_FORMAT} "):], path)
    try:
        n = int(next(ln.split()[2] for ln in lines if ln.startswith("element vertex ")))
        types = {"double": "<f8", "float": "<f4", "int": "<i4"}
        dtype = np.dtype([(ln.split()[2], types[ln.split()[1]]) for ln in lines if ln.startswith("property ")])
    except (StopIteration, KeyError, IndexError, ValueError) as exc:
        raise MapFileError(f"{path}: malformed PLY header: {exc}") from exc
    body = raw[end + len(b"end_header\n"):]
    if n < 0 or len(body) < n * dtype.itemsize:
        raise MapFileError(f"{path}: {len(body)} bytes of vertex data, {n} vertices need {n * dtype.itemsize}")
    rec = np.frombuffer(body[: n * dtype.itemsize], dtype)
    return _from_records(rec, int(meta.get("dim", 3)), meta)


def _load_csv(path: Path) -> LandmarkMap:
    with path.open() as fh:
        first = fh.readline()
        names = fh.readline().strip().split(",")
        if not first.startswith(f"# {MAP_FORMAT} "):
            raise MapFileError(f"{path}: a CSV file, but not an mrslam landmark map")
        meta = _header_meta(first[len(f"# {MAP_FORMAT} "):], path)
        try:
            table = np.loadtxt(fh, delimiter=",", ndmin=2)
        except ValueError as exc:
            raise MapFileError(f"{path}: malformed CSV: {exc}") from exc
    dim = int(meta.get("dim", 3))
    d = sum(1 for c in names if c[:1] == "d" and c[1:].isdigit())
    if names != _columns(dim, d) or (table.size and table.shape[1] != len(names)):
        raise MapFileError(f"{path}: columns {names} are not those of a dim-{dim} map")
    table = table.reshape(-1, len(names))
    rec = np.zeros(table.shape[0], _record_dtype(dim, d))
    for i, c in enumerate(names):
        rec[c] = table[:, i]
    return _from_records(rec, dim, meta)


def load_map(path: str | Path) -> LandmarkMap:
    """Read a map written by :func:`save_map`, or the best particle's map of a checkpoint or run
    folder.

    Raises:
        MapFileError: unreadable file, unknown format, or not an mrslam map/checkpoint.
    """
    path = Path(path)
    if path.is_dir():
        return map_from_checkpoint(path)
    if not path.is_file():
        raise MapFileError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".ply":
        return _load_ply(path)
    if suffix == ".csv":
        return _load_csv(path)
    return _load_npz(path)


# ----------------------------------------------------------------------------- summary, CLI
def summary(lmap: LandmarkMap) -> str:
    """A few lines: landmark count, dimension, extent, observation counts, uncertainty."""
    lines = [f"{len(lmap)} landmarks (dim {lmap.dim}, descriptor length {lmap.descriptor.shape[1]})"]
    for key in ("source", "robots", "model", "best_particle", "steps"):
        if key in lmap.meta:
            lines.append(f"  {key}: {lmap.meta[key]}")
    if len(lmap):
        lo, hi = lmap.mean.min(axis=0), lmap.mean.max(axis=0)
        lines.append("  extent [m]: " + "  ".join(f"{a} {l:.2f}..{h:.2f}" for a, l, h in zip("xyz", lo, hi)))
        c = lmap.count
        lines.append(f"  observations per landmark: median {np.median(c):.0f}, max {c.max()}, "
                     f">= 3: {int((c >= 3).sum())}")
        sigma = np.sqrt(np.clip(np.trace(lmap.cov, axis1=1, axis2=2) / lmap.dim, 0, None))
        lines.append(f"  position σ (rms over axes) [m]: median {np.median(sigma):.3f}, "
                     f"p95 {np.percentile(sigma, 95):.3f}")
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="mrslam map", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    ex = sub.add_parser("export", help="write the best particle's map of a checkpoint or run folder")
    ex.add_argument("source", help="a filter checkpoint (.npz) or a run folder holding one")
    ex.add_argument("--out", required=True, help="map.npz, map.ply or map.csv")
    ld = sub.add_parser("load", help="read a map or checkpoint and print a summary")
    ld.add_argument("file")
    args = ap.parse_args(argv)
    try:
        if args.cmd == "export":
            lmap = map_from_checkpoint(args.source)
            save_map(lmap, args.out)
            print(f"wrote {args.out}: {len(lmap)} landmarks of particle {lmap.meta['best_particle']}")
        else:
            print(summary(load_map(args.file)))
    except (MapFileError, OSError) as exc:
        print(f"mrslam map: {exc}", file=sys.stderr)
        return 2
    return 0
