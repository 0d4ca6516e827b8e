"""Where the generated ROS interfaces live, and the environment node processes need.

``scripts/build_interfaces.sh`` (run by ``make``) generates the interface packages the PyPI
wheels lack (tf2_msgs) into the install prefix ``<venv>/ros_interfaces``:

- ``lib/``: the generated C/C++ type-support libraries (they carry an RPATH to this folder);
- ``lib/python3.11/site-packages/``: the generated Python packages;
- ``share/``: package.xml, the .msg files and the ament index entries.

How ``import tf2_msgs.msg`` works in-process: the script writes
``<venv>/lib/python3.11/site-packages/mrslam_interfaces.pth``. Python reads ``.pth`` files in name
order at start-up, so this one runs before ``ros_wheels_bootstrapper.pth``: it adds the generated
``site-packages`` to ``sys.path`` and prepends ``lib/`` to ``LD_LIBRARY_PATH`` (and the prefix to
``AMENT_PREFIX_PATH``); the bootstrapper then re-executes the interpreter with that
``LD_LIBRARY_PATH``, which rosidl's type-support loader searches. So every interpreter of the venv
(tests, ``mrslam``, ``python -m mrslam_ros.<node>``) imports tf2_msgs with no further set-up.

For processes started some other way (another interpreter, a cleared environment), :func:`node_env`
returns the environment to pass to ``subprocess``; :func:`ensure_interfaces` repairs the current
process as far as that is possible after start-up and otherwise says how to build.
"""

from __future__ import annotations

import importlib
import os
import sys
from collections.abc import Mapping
from pathlib import Path

#: Environment variable naming an interface install prefix explicitly (overrides the venv's).
PREFIX_VARIABLE = "MRSLAM_INTERFACES"
#: The interface packages the project generates.
PACKAGES = ("tf2_msgs",)
BUILD_HINT = "run `make venv` (or scripts/build_interfaces.sh .venv) to generate them"


class InterfacesMissing(RuntimeError):
    """The generated interface packages are not installed or not importable."""


def interfaces_prefix() -> Path | None:
    """The install prefix of the generated interfaces, or None when they were never built.

    ``$MRSLAM_INTERFACES`` if set, else ``<sys.prefix>/ros_interfaces`` (the venv's).
    """
    explicit = os.environ.get(PREFIX_VARIABLE)
    prefix = Path(explicit) if explicit else Path(sys.prefix) / "ros_interfaces"
    return prefix if (prefix / "lib").is_dir() else None


def python_dir(prefix: Path) -> Path:
    """The generated Python packages' folder under ``prefix``."""
    return prefix / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}" / "site-packages"


def _prepend(value: str | None, *parts: str) -> str:
    old = [p for p in (value or "").split(os.pathsep) if p]
    return os.pathsep.join(list(dict.fromkeys([*parts, *old])))


def node_env(base: Mapping[str, str] | None = None, extra: Mapping[str, str] | None = None) -> dict[str, str]:
    """The environment of a node subprocess: ``base`` (default ``os.environ``) with the generated
    interfaces first on PYTHONPATH, LD_LIBRARY_PATH and AMENT_PREFIX_PATH, then ``extra``.

    The ROS wheels' own libraries come from ``base``'s LD_LIBRARY_PATH (set by the bootstrapper in
    this interpreter) or, in a fresh environment, from the bootstrapper of the child's venv.
    PYTHONUNBUFFERED is set so a launcher sees log lines as they are written.
    """
    env = dict(os.environ if base is None else base)
    prefix = interfaces_prefix()
    if prefix is not None:
        env["PYTHONPATH"] = _prepend(env.get("PYTHONPATH"), str(python_dir(prefix)))
        env["LD_LIBRARY_PATH"] = _prepend(env.get("LD_LIBRARY_PATH"), str(prefix / "lib"))
        env["AMENT_PREFIX_PATH"] = _prepend(env.get("AMENT_PREFIX_PATH"), str(prefix), sys.prefix)
    env.setdefault("PYTHONUNBUFFERED", "1")
    env.update(extra or {})
    return env


def ensure_interfaces() -> None:
    """Make the generated packages importable here, or raise with the command that builds them.

    Adds the generated ``site-packages`` to ``sys.path`` and the prefix to LD_LIBRARY_PATH and
    AMENT_PREFIX_PATH of this process when the ``.pth`` file did not (e.g. an interpreter outside
    the venv); the type-support libraries are found through their RPATH and the updated
    LD_LIBRARY_PATH, which rosidl reads when it loads them.

    Raises:
        InterfacesMissing: a package of :data:`PACKAGES` cannot be imported.
    """
    prefix = interfaces_prefix()
    if prefix is not None:
        site = str(python_dir(prefix))
        if site not in sys.path:
            sys.path.append(site)
        os.environ["LD_LIBRARY_PATH"] = _prepend(os.environ.get("LD_LIBRARY_PATH"), str(prefix / "lib"))
        os.environ["AMENT_PREFIX_PATH"] = _prepend(os.environ.get("AMENT_PREFIX_PATH"), str(prefix))
    for pkg in PACKAGES:
        try:
            importlib.import_module(f"{pkg}.msg")
        except ImportError as exc:
            where = f"not in {prefix}" if prefix is not None else "never generated"
            raise InterfacesMissing(f"{pkg} is {where} ({exc}); {BUILD_HINT}") from exc
