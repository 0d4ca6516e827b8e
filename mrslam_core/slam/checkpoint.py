"""Checkpoints of the central filter: one ``.npz`` file that loads without executing code.

A checkpoint holds everything :class:`~mrslam_core.slam.filter.MultiRobotFastSLAM` needs to
continue exactly where it stopped: the particle poses (M, K, 3), log weights and accumulated log
likelihoods (M,), the landmark store (copy-on-write chunk pool, chunk tables, per-slot
descriptors, reference positions and track ids), the robot registry and last stamps, the drop
counters, the random generator's state and the config. A filter loaded from a checkpoint and the
filter that wrote it give bit-identical results for the same later inputs.

Layout (see docs/checkpoint.md): ``np.savez`` members, all plain numeric arrays (never object
arrays, so ``np.load(..., allow_pickle=False)`` reads it), plus ``header``: the UTF-8 bytes (uint8)
of a JSON object with the format version, the config (the YAML/dict form of
:mod:`mrslam_core.configio`), the robot registry, counters, the bit generator state and the
caller's ``extra`` values. The file is written to a temporary file in the same folder, flushed to
disk and renamed over the target (``os.replace``), so a crash mid-write leaves the previous
checkpoint intact.
"""

from __future__ import annotations

import dataclasses
import typing

import json
import os
import tempfile
import time
import zipfile
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from mrslam_core.configio import ConfigError, from_dict, to_dict
from mrslam_core.errors import InputError
from mrslam_core.slam.config import FilterConfig
from mrslam_core.slam.filter import MultiRobotFastSLAM
from mrslam_core.slam.landmarks import STATE_ARRAYS, LandmarkStore
from mrslam_core.slam.models import ObservationModel
from mrslam_core.slam.tracks import TrackMemory

FORMAT = "mrslam-filter-checkpoint"
FORMAT_VERSION = 3
#: versions this mrslam reads: 1 stored the landmark store's one-level chunk table (regrouped
#: into nodes on load), 2 its two-level table (:meth:`LandmarkStore.state`), 3 the same filter
#: members with the central mapper's state by part in ``extra``, local filters included
#: (:mod:`mrslam_core.pipelines.central`; it still resumes from a version 2 file)
READ_VERSIONS = (1, 2, 3)

#: Filter arrays saved as ``filter.<name>``.
FILTER_ARRAYS = ("poses", "log_w", "score")
#: Landmark store arrays saved as ``store.<name>`` (pools and nodes up to the last in use).
STORE_ARRAYS = STATE_ARRAYS
#: Filter attributes saved or rebuilt one by one. Every other attribute of the filter (its
#: counters, flags and per-robot arrays) is saved by type (see :func:`_other_state`): scalars in
#: the header's ``attributes``, arrays as ``attr.<name>``, ``{int: array}`` dicts as
#: ``dict.<name>.keys``/``.values``; an attribute of another type makes saving fail loudly.
FILTER_ATTRIBUTES = frozenset(
    FILTER_ARRAYS + ("config", "robots", "index", "model", "rng", "landmarks", "last_stamp", "dropped", "tracks")
)
#: Arrays of each robot's :class:`~mrslam_core.slam.tracks.TrackMemory`, saved as
#: ``tracks.<k>.<name>`` (k: the robot's index); its set counter is in the header.
TRACK_ARRAYS = ("ids", "slots", "last")
#: Store attributes restored or rebuilt (``_tree``/``_dtree`` and their live lists are caches,
#: rebuilt lazily from ``ref`` and ``descriptor``).
STORE_ATTRIBUTES = frozenset(
    STORE_ARRAYS + ("dim", "chunk", "fanout", "descriptor_dim", "size", "_grid", "_dindex", "_free_nodes", "_free_chunks", "_scratch")
)


class CheckpointError(InputError, ValueError):
    """A checkpoint file that cannot be written or read (wrong format, version or content)."""


def _json_default(value: Any) -> Any:
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    if isinstance(value, np.bool_):
        return bool(value)
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def filter_state(filter: MultiRobotFastSLAM) -> dict[str, Any]:
    """The filter's complete state as plain values: ``header``, a JSON-able dict (config, model,
    robots, last stamps, drop counters, scalar attributes, track memory counters, the bit
    generator's state, the store's sizes), and every array by its member name (``filter.*``,
    ``store.*``, ``attr.*``, ``dict.*``, ``tracks.*``; see docs/checkpoint.md). A checkpoint
    file is this plus the format fields and the caller's extra values; :func:`filter_from_state`
    rebuilds the filter.

    Raises:
        CheckpointError: a filter attribute that cannot be stored without pickle.
    """
    store = filter.landmarks
    arrays: dict[str, np.ndarray] = {}
    for name in FILTER_ARRAYS:
        arrays[f"filter.{name}"] = np.asarray(getattr(filter, name))
    for name, value in store.state().items():
        arrays[f"store.{name}"] = value
    attributes = _other_state(filter, arrays)
    for k, memory in filter.tracks.items():
        for name in TRACK_ARRAYS:
            arrays[f"tracks.{k}.{name}"] = getattr(memory, name)
    header = {
        "config": to_dict(filter.config),
        "model": filter.model.name,
        "robots": list(filter.robots),
        "last_stamp_ns": {name: int(t) for name, t in filter.last_stamp.items()},
        "dropped": {str(k): int(v) for k, v in filter.dropped.items()},
        "attributes": attributes,
        "tracks": {str(k): memory.sets for k, memory in filter.tracks.items()},
        "rng": filter.rng.bit_generator.state,
        "store": {"dim": int(store.dim), "chunk": int(store.chunk), "fanout": int(store.fanout),
                  "descriptor_dim": int(store.descriptor_dim), "size": int(store.size)},
    }
    return {"header": header, **arrays}


def save_checkpoint(filter: MultiRobotFastSLAM, path: str | Path, extra: dict[str, Any] | None = None) -> Path:
    """Write the filter's complete state to ``path`` atomically.

    Args:
        filter: the filter to save (not modified).
        path: target file; the ``.npz`` format is used whatever the suffix.
        extra: caller's values stored beside the filter (e.g. a node's wall time or its robots'
            last odometry). Values that are numpy arrays of a numeric or bool dtype are stored
            as arrays ``extra.<key>``; every other value must be JSON serialisable.

    Returns:
        the path written.

    Raises:
        CheckpointError: ``extra`` holds something that cannot be stored without pickle.
    """
    path = Path(path)
    state = filter_state(filter)
    arrays: dict[str, np.ndarray] = {k: v for k, v in state.items() if k != "header"}
    extra_json: dict[str, Any] = {}
    for key, value in (extra or {}).items():
        if not isinstance(key, str):
            raise CheckpointError(f"extra keys must be strings, got {key!r}")
        if isinstance(value, np.ndarray):
            if value.dtype.kind not in "biuf":
                raise CheckpointError(f"extra[{key!r}]: arrays of dtype {value.dtype} need pickle")
            arrays[f"extra.{key}"] = value
        else:
            extra_json[key] = value
    header = {
        "format": FORMAT,
        "version": FORMAT_VERSION,
        "written_unix_s": time.time(),
        **state["header"],
        "extra": extra_json,
        "extra_arrays": sorted(k[len("extra."):] for k in arrays if k.startswith("extra.")),
    }
    try:
        text = json.dumps(header, default=_json_default, allow_nan=True)
    except (TypeError, ValueError) as exc:
        raise CheckpointError(f"checkpoint header is not JSON serialisable: {exc}") from exc
    arrays["header"] = np.frombuffer(text.encode("utf-8"), np.uint8)

    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, **arrays)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    try:  # make the rename itself durable
        dfd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError:
        pass
    return path


_READ_ERRORS = (OSError, ValueError, EOFError, zipfile.BadZipFile)


def _other_state(filter: MultiRobotFastSLAM, arrays: dict[str, np.ndarray]) -> dict[str, Any]:
    """Save every filter attribute not in FILTER_ATTRIBUTES by its type; returns the scalars.

    Raises:
        CheckpointError: an attribute of a type this format cannot hold without pickle.
    """
    scalars: dict[str, Any] = {}
    for name, value in vars(filter).items():
        if name in FILTER_ATTRIBUTES:
            continue
        if value is None or isinstance(value, (bool, int, float, str, np.number, np.bool_)):
            scalars[name] = value.item() if isinstance(value, (np.number, np.bool_)) else value
        elif isinstance(value, np.ndarray) and value.dtype.kind in "biuf":
            arrays[f"attr.{name}"] = value
        elif isinstance(value, dict) and all(isinstance(k, (int, np.integer)) for k in value) and all(
            isinstance(v, np.ndarray) and v.dtype.kind in "biuf" for v in value.values()
        ) and len({v.shape for v in value.values()}) <= 1:
            keys = sorted(value)
            arrays[f"dict.{name}.keys"] = np.array(keys, np.int64)
            arrays[f"dict.{name}.values"] = (
                np.stack([value[k] for k in keys]) if keys else np.zeros((0,))
            )
        else:
            raise CheckpointError(
                f"filter attribute {name!r} ({type(value).__name__}) has no checkpoint form; "
                "teach mrslam_core/slam/checkpoint.py to save it"
            )
    return scalars


def _restore_other_state(path, slam: MultiRobotFastSLAM, scalars: dict[str, Any], arrays) -> None:
    """Set the attributes :func:`_other_state` saved (those the loading filter still has)."""
    known = set(vars(slam))
    for name, value in scalars.items():
        if name in known:
            setattr(slam, name, value)
    for key, value in arrays.items():
        if key.startswith("attr.") and key[5:] in known:
            setattr(slam, key[5:], np.array(value))
        elif key.startswith("dict.") and key.endswith(".keys") and key[5:-5] in known:
            name = key[5:-5]
            values = arrays.get(f"dict.{name}.values")
            if values is None or (value.size and values.shape[0] != value.size):
                raise CheckpointError(f"{path}: dict.{name}: keys and values do not match")
            setattr(slam, name, {int(k): np.array(v) for k, v in zip(value, values)})


def read_header(path: str | Path) -> dict[str, Any]:
    """The JSON header of a checkpoint (format, version, config, robots, counters, extra)."""
    return _read(path)[0]


def _read(path: str | Path) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """(header, arrays) of a checkpoint file, every member read and checked to be numeric."""
    try:
        data = np.load(Path(path), allow_pickle=False)
    except _READ_ERRORS as exc:
        raise CheckpointError(f"{path}: not a readable .npz checkpoint: {exc}") from exc
    if not isinstance(data, np.lib.npyio.NpzFile):
        raise CheckpointError(f"{path}: a single .npy array, not an .npz checkpoint")
    with data:
        header = _header(data, path)
        try:
            arrays = {name: data[name] for name in data.files if name != "header"}
        except _READ_ERRORS as exc:
            raise CheckpointError(f"{path}: damaged member: {exc}") from exc
    return header, arrays


def _header(data, path) -> dict[str, Any]:
    if "header" not in data.files:
        raise CheckpointError(f"{path}: no header member; not an mrslam checkpoint")
    try:
        header = json.loads(data["header"].tobytes().decode("utf-8"))
    except (*_READ_ERRORS, UnicodeDecodeError) as exc:
        raise CheckpointError(f"{path}: header is not valid JSON: {exc}") from exc
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        raise CheckpointError(f"{path}: not an mrslam filter checkpoint")
    if header.get("version") not in READ_VERSIONS:
        raise CheckpointError(
            f"{path}: checkpoint format version {header.get('version')!r}, this mrslam reads {READ_VERSIONS}"
        )
    return header


def load_checkpoint(
    path: str | Path, model: ObservationModel | None = None
) -> tuple[MultiRobotFastSLAM, dict[str, Any]]:
    """Rebuild the filter a checkpoint was written from.

    Args:
        path: a file written by :func:`save_checkpoint`.
        model: the observation model, when the saved filter used one that is not the config's
            ``observation_model`` (its name must match the saved one).

    Returns:
        (filter, extra): the filter, in exactly the saved state, and the ``extra`` values passed
        to :func:`save_checkpoint` (arrays as numpy arrays).

    Raises:
        CheckpointError: not a checkpoint, another format version, or inconsistent content.
    """
    header, arrays = _read(path)
    slam = filter_from_state({"header": header, **arrays}, model, path)
    try:
        extra = dict(header["extra"])
        for key in header["extra_arrays"]:
            extra[key] = np.array(arrays[f"extra.{key}"])
    except KeyError as exc:
        raise CheckpointError(f"{path}: missing {exc}") from exc
    return slam, extra


def filter_from_state(state: dict[str, Any], model: ObservationModel | None = None,
                      source: str | Path = "filter state") -> MultiRobotFastSLAM:
    """The filter :func:`filter_state` described, in exactly that state.

    Args:
        state: ``header`` and the arrays by member name, as :func:`filter_state` returns them
            (other members are ignored).
        model: as for :func:`load_checkpoint`.
        source: where the state comes from, for error messages.

    Raises:
        CheckpointError: a missing or inconsistent member.
    """
    try:
        header = state["header"]
        config = from_dict(FilterConfig, _known_keys(FilterConfig, header["config"]))
    except ConfigError as exc:
        raise CheckpointError(f"{source}: saved config: {exc}") from exc
    except KeyError as exc:
        raise CheckpointError(f"{source}: header lacks {exc}") from exc
    try:
        return _rebuild(source, header, state, config, model)
    except KeyError as exc:
        raise CheckpointError(f"{source}: missing {exc}") from exc
    except (TypeError, ValueError, IndexError, AttributeError) as exc:
        if isinstance(exc, CheckpointError):
            raise
        raise CheckpointError(f"{source}: {exc}") from exc


def _known_keys(cls, data):
    """``data`` without the keys ``cls`` (a config dataclass, nested) no longer has: a checkpoint
    written before an option was removed still resumes (the option was off, or it is gone for good)."""
    if not (dataclasses.is_dataclass(cls) and isinstance(data, dict)):
        return data
    hints = typing.get_type_hints(cls)
    return {f.name: _known_keys(hints[f.name], data[f.name]) for f in dataclasses.fields(cls) if f.name in data}


def _rebuild(path, header, arrays, config, model) -> MultiRobotFastSLAM:
    robots = [str(r) for r in header["robots"]]
    k, m = len(robots), config.num_particles
    if model is not None and model.name != header["model"]:
        raise CheckpointError(f"{path}: saved with model {header['model']!r}, given {model.name!r}")
    if model is None and header["model"] != config.observation_model:
        raise CheckpointError(
            f"{path}: saved with model {header['model']!r} (not the config's); pass model="
        )
    expect = {"filter.poses": ((m, k, 3), "f"), "filter.log_w": ((m,), "f"), "filter.score": ((m,), "f")}
    for name, (shape, kind) in expect.items():
        a = arrays[name]
        if a.shape != shape or a.dtype.kind != kind:
            raise CheckpointError(f"{path}: {name} is {a.dtype}{a.shape}, expected float {shape}")
    slam = MultiRobotFastSLAM(config, robots, np.zeros((k, 3)), model)
    for name in FILTER_ARRAYS:
        setattr(slam, name, np.array(arrays[f"filter.{name}"]))
    slam.last_stamp = {str(r): int(t) for r, t in header["last_stamp_ns"].items()}
    slam.dropped = Counter({str(r): int(n) for r, n in header["dropped"].items()})
    _restore_other_state(path, slam, header["attributes"], arrays)
    for key, sets in header.get("tracks", {}).items():
        memory = TrackMemory(m, config.association.track_memory)
        for name in TRACK_ARRAYS:
            setattr(memory, name, np.array(arrays[f"tracks.{key}.{name}"], np.int64))
        if memory.slots.shape != (m, memory.ids.size) or memory.last.shape != memory.ids.shape:
            raise CheckpointError(f"{path}: tracks.{key} arrays do not match {m} particles")
        memory.sets = int(sets)
        slam.tracks[int(key)] = memory
    state = header["rng"]
    bit_gen = getattr(np.random, str(state["bit_generator"]), None)
    if not (isinstance(bit_gen, type) and issubclass(bit_gen, np.random.BitGenerator)):
        raise CheckpointError(f"{path}: unknown bit generator {state['bit_generator']!r}")
    gen = bit_gen()
    gen.state = state
    slam.rng = np.random.Generator(gen)
    slam.landmarks = _rebuild_store(path, header["store"], arrays, m)
    return slam


def _rebuild_store(path, meta: dict[str, Any], arrays: dict[str, np.ndarray], m: int) -> LandmarkStore:
    state = {name: arrays[f"store.{name}"] for name in STORE_ARRAYS if f"store.{name}" in arrays}
    try:
        store = LandmarkStore.from_state(state, int(meta["dim"]), int(meta["chunk"]), int(meta["descriptor_dim"]),
                                         int(meta["size"]), int(meta.get("fanout", 32)))
    except ValueError as exc:
        raise CheckpointError(f"{path}: inconsistent landmark store: {exc}") from exc
    if store.num_particles != m:
        raise CheckpointError(f"{path}: inconsistent landmark store: table rows != particles")
    return store
