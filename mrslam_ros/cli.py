"""The ``mrslam`` command: one sub-command per job, each a ``main(argv) -> int`` in its own module.

Sub-commands that need ROS import rclpy only when they run, so ``mrslam mrclam`` and
``mrslam bench`` work where rclpy is not installed.

A user's mistake (a missing or wrong path, a value out of range, a folder that is not a bag, a bad
option) ends in one line naming the problem and exit status 2: every command's argparse errors and
:class:`~mrslam_core.errors.InputError` (config, dataset, bag, checkpoint, map and world file
errors) and missing or unreadable files. Any other exception is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from contextlib import contextmanager

from mrslam_core.errors import InputError

COMMANDS = {
    "demo": ("mrslam_ros.demo", "closed loop in simulation: sim, frontends, SLAM, exploration"),
    "launch": ("mrslam_ros.launch", "start the nodes a config YAML lists"),
    "replay": ("mrslam_ros.replay", "play a rosbag2 recording into the nodes (or --offline)"),
    "mrclam": ("mrslam_core.pipelines.mrclam", "run the filter on a UTIAS MR.CLAM dataset"),
    "dataset": ("mrslam_ros.dataset_cli", "public stereo datasets (KITTI, EuRoC): import into a bag, or run"),
    "team": ("mrslam_core.pipelines.team", "a simulated team, closed loop, in one process (no ROS)"),
    "bench": ("mrslam_core.bench", "benchmarks: mrslam bench {filter,frontend,sim,...}"),
    "experiment": ("mrslam_core.experiments", "reproducible experiments behind docs/results.md"),
    "map": ("mrslam_core.mapio", "export or inspect the best particle's landmark map"),
}


def usage() -> str:
    lines = ["usage: mrslam COMMAND [ARGS]", "", "commands:"]
    lines += [f"  {name:<8} {doc}" for name, (_, doc) in COMMANDS.items()]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(usage())
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"mrslam: unknown command {name!r}\n\n{usage()}", file=sys.stderr)
        return 2
    try:
        with _argparse_errors_raise():
            module = importlib.import_module(COMMANDS[name][0])
            return int(module.main(rest) or 0)
    except InputError as exc:
        print(f"mrslam {name}: {exc}", file=sys.stderr)
    except (FileNotFoundError, NotADirectoryError, IsADirectoryError, PermissionError, FileExistsError) as exc:
        print(f"mrslam {name}: {exc.strerror or exc}: {exc.filename}", file=sys.stderr)
    return 2


@contextmanager
def _argparse_errors_raise():
    """Within: an argparse error of any sub-command raises InputError (its one-line message and
    a pointer to --help) instead of printing the usage block."""

    def error(parser: argparse.ArgumentParser, message: str):
        raise InputError(f"{message} (see {parser.prog} --help)")

    saved = argparse.ArgumentParser.error
    argparse.ArgumentParser.error = error  # type: ignore[method-assign]
    try:
        yield
    finally:
        argparse.ArgumentParser.error = saved  # type: ignore[method-assign]


if __name__ == "__main__":
    sys.exit(main())
