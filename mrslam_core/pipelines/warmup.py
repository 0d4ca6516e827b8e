"""Compile the numba kernels of the shipped profiles into numba's on-disk cache.

numba compiles a kernel on its first call in a process unless its cache (``__pycache__`` beside
the source) holds it. On a fresh clone nothing is cached, so the central node of the first
``make demo`` compiled for 23 s while the simulator's clock already ran, and every test process
compiled the same kernels again. ``make venv`` runs ``python -m mrslam_core.pipelines.warmup``
beside the bytecode and interface builds instead: the filter's kernels under the simulated team's,
the real stereo robot's and MR.CLAM's filter configs, and the map check's frame likelihood.
"""

from __future__ import annotations

import time

from mrslam_core.configio import PROFILES, load_profile
from mrslam_core.pipelines.central import map_move
from mrslam_core.pipelines.dataset import DatasetRunConfig
from mrslam_core.pipelines.mrclam import MrclamConfig
from mrslam_core.pipelines.team import TeamConfig
from mrslam_core.slam.warmup import warm_up


def main() -> float:
    """Call every kernel once under each shipped profile's filter config; returns the wall time [s]."""
    t0 = time.perf_counter()
    real = load_profile(DatasetRunConfig, PROFILES / "real_stereo.yaml")
    for cfg in (TeamConfig().filter, real.filter, MrclamConfig().filter):
        warm_up(cfg)
    map_move.warm_up()
    return time.perf_counter() - t0


if __name__ == "__main__":
    print(f"numba kernels compiled into their cache in {main():.1f} s")
