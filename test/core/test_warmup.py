"""The set-up's numba warm-up (``python -m mrslam_core.pipelines.warmup``, run by ``make venv``)
reaches every compiled kernel that Python calls (the private helpers are compiled into their
callers), so no node or test compiles one on its first call."""

import json
import subprocess
import sys

# in a fresh interpreter: in this one, earlier tests may have compiled the kernels already
PROBE = """
import importlib, json
from numba.core.registry import CPUDispatcher
from mrslam_core.pipelines import warmup
warmup.main()
modules = ("mrslam_core.slam.association_kernels", "mrslam_core.slam.stereo_kernels",
           "mrslam_core.slam.proposal_kernels", "mrslam_core.slam.store_kernels",
           "mrslam_core.pipelines.central.map_move_kernels")
kernels = [(name, attr, obj) for name in modules for attr, obj in vars(importlib.import_module(name)).items()
           if isinstance(obj, CPUDispatcher) and obj.__module__ == name and not attr.startswith("_")]
print(json.dumps({"kernels": len(kernels), "missed": [f"{n}.{a}" for n, a, o in kernels if not o.signatures]}))
"""


def test_the_warm_up_compiles_every_kernel():
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, check=True, timeout=300)
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["kernels"] >= 20
    assert not got["missed"], f"kernels the warm-up does not call: {got['missed']}"
