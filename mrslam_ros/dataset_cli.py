"""``mrslam dataset import|run FORMAT PATH``: a public stereo sequence as a rosbag2, or straight
through the frontends and the central mapper into a run folder.

``import`` writes a bag:

FORMAT is ``kitti`` or ``euroc`` (:mod:`mrslam_core.datasets.stereo`); the bag has the simulator's
topics and frames (:mod:`mrslam_ros.dataset_bag`), so ``mrslam replay BAG`` feeds the frontend
nodes. ``--split K`` cuts the sequence into K consecutive segments driven at the same time by
robots ``<prefix>1`` .. ``<prefix>K`` (each starting at its ground-truth pose in the whole
sequence's map frame). A user mistake prints one line ``mrslam dataset import: <problem>`` on
stderr and returns 2. No ROS is needed.

``run`` (:mod:`mrslam_core.pipelines.dataset`) runs the sequence offline with the real stereo
profile (``config/real_stereo.yaml``, or ``--config``) and writes report.json, TUM trajectories,
plots and config.yaml into ``--out``.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

from mrslam_core.configio import PROFILES
from mrslam_core.datasets.stereo import FORMATS, DatasetError, open_sequence
from mrslam_ros.bag import STORAGES, BagError

PROG = "mrslam dataset import"
RUN = "mrslam dataset run"
#: the real stereo robot profile, used by ``run`` unless ``--config`` names another
PROFILE = PROFILES / "real_stereo.yaml"


class _UsageError(Exception):
    """A command line argparse rejects (reported as one line, not argparse's usage block)."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # noqa: D102 - argparse hook
        raise _UsageError(message)


def _sequence_parser(prog: str, description: str, out: str) -> argparse.ArgumentParser:
    """A parser of FORMAT PATH --out, the words both sub-commands start with."""
    ap = _Parser(prog=prog, description=description)
    ap.add_argument("format", metavar="FORMAT", help=f"dataset layout: {' or '.join(FORMATS)}")
    ap.add_argument("path", metavar="PATH", type=Path, help="the sequence folder")
    ap.add_argument("--out", type=Path, required=True, help=out)
    return ap


def _parser() -> argparse.ArgumentParser:
    ap = _sequence_parser(PROG, "write a KITTI odometry or EuRoC/ASL stereo sequence into a rosbag2 with the "
                                "nodes' topics", "bag folder to create (must not exist)")
    ap.add_argument("--storage", choices=sorted(STORAGES), default="mcap", help="rosbag2 storage (default mcap)")
    ap.add_argument("--split", type=int, default=1, metavar="K",
                    help="cut the sequence into K segments, one robot each, all starting at once (default 1)")
    ap.add_argument("--robots-prefix", default="robot", metavar="PREFIX",
                    help="robots are named PREFIX1 .. PREFIXK (default robot)")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    return ap


def _parse(parser: argparse.ArgumentParser, argv: list[str]) -> argparse.Namespace | int:
    """The parsed arguments, or the exit status: 2 after one line naming the mistake, 0 after --help."""
    try:
        return parser.parse_args(argv)
    except _UsageError as exc:
        print(f"{parser.prog}: {exc}", file=sys.stderr)
        return 2
    except SystemExit as exc:  # --help
        return int(exc.code or 0)


def import_main(argv: list[str]) -> int:
    """Run ``mrslam dataset import`` with ``argv`` (the words after ``import``).

    Returns:
        0 when the bag was written, 2 on a user mistake (one line on stderr).
    """
    from mrslam_ros.dataset_bag import write_dataset_bag

    args = _parse(_parser(), argv)
    if isinstance(args, int):
        return args
    try:
        if args.out.exists():
            raise BagError(f"--out {args.out} exists already (not overwriting)")
        if not args.robots_prefix or "/" in args.robots_prefix:
            raise BagError(f"--robots-prefix {args.robots_prefix!r} must be a non-empty name without '/'")
        seq = open_sequence(args.format, args.path)
        if not 1 <= args.split <= len(seq):
            raise DatasetError(f"--split {args.split}: need 1 <= K <= {len(seq)} (the frames of {args.path})")
        parts = seq.split(args.split)
        robots = [(f"{args.robots_prefix}{j + 1}", part) for j, part in enumerate(parts)]
        for note in seq.notes:
            print(f"{PROG}: note: {note}", file=sys.stderr)
    except (DatasetError, BagError) as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2
    try:
        write_dataset_bag(robots, args.out, storage=args.storage, progress=not args.quiet)
    except (DatasetError, BagError) as exc:
        shutil.rmtree(args.out, ignore_errors=True)  # it did not exist before: an unfinished bag of ours
        print(f"{PROG}: {exc} (the unfinished bag {args.out} was removed)", file=sys.stderr)
        return 2
    gt = "with" if seq.ground_truth is not None else "without"
    print(f"wrote {args.out} ({args.storage}): {len(seq)} stereo pairs of {seq.name} ({seq.format}, {gt} ground truth) "
          f"as {', '.join(f'{r} ({len(p)})' for r, p in robots)}")
    return 0


def _run_parser() -> argparse.ArgumentParser:
    ap = _sequence_parser(RUN, "run a KITTI odometry or EuRoC/ASL stereo sequence through the stereo frontends "
                               "and the central mapper, offline, and write a run folder", "run folder to write")
    ap.add_argument("--config", type=Path, default=PROFILE,
                    help="profile YAML (the central mapper's keys, frontend, and the run's split, join_unknown, "
                         "max_frames); default config/real_stereo.yaml")
    ap.add_argument("--split", type=int, metavar="K", help="K robots, one per consecutive segment")
    ap.add_argument("--unknown-start", action="store_true", help="robots 2..K start unknown and join by map alignment")
    ap.add_argument("--frames", type=int, metavar="N", help="use only the first N frames")
    ap.add_argument("--seed", type=int, help="the filter's seed instead of the profile's")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    return ap


def run_main(argv: list[str]) -> int:
    """Run ``mrslam dataset run`` with ``argv`` (the words after ``run``): 0, or 2 with one line on
    stderr for a user mistake."""
    from mrslam_core.configio import ConfigError, load_profile
    from mrslam_core.evaluation.report import write_run
    from mrslam_core.pipelines.dataset import DatasetRunConfig, run

    args = _parse(_run_parser(), argv)
    if isinstance(args, int):
        return args
    over: dict = {}
    for key, value in (("split", args.split), ("max_frames", args.frames)):
        if value is not None:
            over[key] = value
    if args.unknown_start:
        over["join_unknown"] = True
    if args.seed is not None:
        over["filter"] = {"seed": args.seed}
    try:
        cfg = load_profile(DatasetRunConfig, args.config, over)
        seq = open_sequence(args.format, args.path)
        if not 1 <= cfg.split <= len(seq):
            raise DatasetError(f"--split {cfg.split}: need 1 <= K <= {len(seq)} (the frames of {args.path})")
    except (ConfigError, ValueError) as exc:  # DatasetError is a ValueError, as are the configs' checks
        print(f"{RUN}: {exc}", file=sys.stderr)
        return 2
    for note in seq.notes:
        print(f"{RUN}: note: {note}", file=sys.stderr)
    bar = None
    if not args.quiet:
        from tqdm import tqdm

        bar = tqdm(total=1, unit="frame", desc=seq.name, leave=False)

    def progress(done: int, total: int) -> None:
        bar.total = total
        bar.update(done - bar.n)

    res = run(seq, cfg, progress if bar is not None else None)
    if bar is not None:
        bar.close()
    report = write_run(args.out, res["trajectories"], cfg, res["update_ms"], res["landmarks"],
                       extra={"dataset": {"format": seq.format, "path": str(args.path), "name": seq.name,
                                          "frames": len(seq), "notes": list(seq.notes)},
                              "frontend": res["robots"], "frontend_ms_mean": res["frontend_ms_mean"],
                              "dropped": res["dropped"], "merges": res["merges"], "relocalizations": res["relocalizations"],
                              "wall_s": res["wall_s"],
                              "start_poses": res["start_poses"]})
    for name, r in report["robots"].items():
        f = res["robots"].get(name, {})
        line = f"  {name}: {r['poses']} updates"
        if not r["poses"] and name in cfg_unknown(report):
            line += " (not merged into the map: its map never aligned with the team's)"
        if "ate_rmse_m" in r:
            line += f", ATE {r['ate_rmse_m']:.3f} m (visual odometry {r['odom_ate_rmse_m']:.3f} m)"
        if "vo_endpoint_error_m" not in f and "vo_end_translation_m" in f:
            line += (f"; visual odometry ends {1e3 * f['vo_end_translation_m']:.1f} mm and "
                     f"{f['vo_end_rotation_deg']:.2f}° from its start")
        if "vo_endpoint_error_m" in f:
            line += (f"; visual odometry end point {f['vo_endpoint_error_m']:.3f} m "
                     f"({f['vo_endpoint_error_pct']:.2f} % of {f['distance_m']:.1f} m), heading {f['vo_heading_error_deg']:+.2f}°")
        print(line)
    u = report["update_ms"]
    print(f"  {report['landmarks']} landmarks; frontend {res['frontend_ms_mean']:.1f} ms a frame; filter step p50 "
          f"{u['p50']:.1f} p95 {u['p95']:.1f} ms; wall {res['wall_s']:.1f} s")
    print(f"report: {args.out / 'report.json'}")
    return 0


def cfg_unknown(report: dict) -> list[str]:
    """The robots a run's report lists as starting unknown."""
    return list(report["config"].get("unknown_start", []))


def main(argv: list[str]) -> int:
    """``mrslam dataset import|run ...``."""
    if argv and argv[0] == "import":
        return import_main(argv[1:])
    if argv and argv[0] == "run":
        return run_main(argv[1:])
    if argv and argv[0] in ("-h", "--help"):
        print("usage: mrslam dataset import|run FORMAT PATH --out OUT [options]  (mrslam dataset import -h)")
        return 0
    print("mrslam dataset: expected 'import' or 'run' (mrslam dataset import|run FORMAT PATH --out OUT)", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
