"""``mrslam bench frontend``: speed and accuracy of the stereo frontend per detector/descriptor.

- Speed: mean/p95 ms of ``Frontend.step`` on 640×480 stereo pairs (the 30 EuRoC V1_01 pairs of
  ../shared/data/euroc_v101_micro, rectified once and cropped to 640×480, so the step does no
  remap), single-threaded: OpenCV with cv2.setNumThreads(1) and BLAS with one thread (the
  benchmark re-runs itself with OPENBLAS_NUM_THREADS=1 etc. when they are not set).
- Speed on real driving imagery: the same on the KITTI odometry excerpt's 51 pairs (1226×370,
  ../shared/data/kitti_excerpt) with the real stereo profile (config/real_stereo.yaml), the
  visual odometry included (it runs inside the step).
- Stereo accuracy: fraction of accepted matches within 1 px of Middlebury ground truth
  (skimage.data.stereo_motorcycle).
- Descriptor distinctiveness (as 002's Table V): the EuRoC left image against itself warped by a
  known homography; nearest-neighbour matches with squared distance ≤ E0, fraction correct
  (within 2 px of the true position) and number of matches per E0.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from mrslam_core.frontend import (
    FeatureExtractor, Frontend, FrontendConfig, StereoRig, descriptor_distance, load_euroc_stereo,
)
from mrslam_core.frontend.matching import match_stereo

COMBOS = [(d, e) for d in ("harris", "orb", "sift") for e in ("usurf", "orb", "sift")]
E0S = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0)
_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def data_root() -> Path:
    """../shared/data beside the repository root."""
    return Path(__file__).resolve().parents[3] / "shared" / "data"


def euroc_pairs(folder: Path) -> tuple[StereoRig, list[tuple[np.ndarray, np.ndarray, int]]]:
    """The raw EuRoC rig and its (left, right, stamp_ns) grey pairs in time order."""
    rig = load_euroc_stereo(folder)
    pairs = []
    for p in sorted((folder / "cam0").glob("*.png")):
        left = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        right = cv2.imread(str(folder / "cam1" / p.name), cv2.IMREAD_GRAYSCALE)
        pairs.append((left, right, int(p.stem)))
    return rig, pairs


def cropped_rectified(folder: Path, width: int = 640, height: int = 480):
    """EuRoC pairs rectified once and centre-cropped to width × height, with their rig."""
    rig, pairs = euroc_pairs(folder)
    x0 = (rig.width - width) // 2
    y0 = (rig.height - height) // 2
    out = []
    for left, right, stamp in pairs:
        lr, rr = rig.rectify(left, right)
        out.append((np.ascontiguousarray(lr[y0:y0 + height, x0:x0 + width]),
                    np.ascontiguousarray(rr[y0:y0 + height, x0:x0 + width]), stamp))
    crop_rig = StereoRig.rectified(width, height, rig.f, rig.cx - x0, rig.cy - y0, rig.baseline,
                                   rig.t_base_rect)
    return crop_rig, out


def time_frontend(rig: StereoRig, pairs, cfg: FrontendConfig, repeats: int = 2) -> dict:
    """Mean / p95 ms per pair of Frontend.step, and the mean counts per pair."""
    times, stereo, obs = [], [], []
    for rep in range(repeats + 1):
        fe = Frontend(rig, cfg)
        for left, right, stamp in pairs:
            t0 = time.perf_counter()
            o, _ = fe.step(left, right, stamp)
            dt = time.perf_counter() - t0
            if rep > 0:  # the first pass warms caches up
                times.append(dt * 1e3)
                stereo.append(len(fe.last_frame.xy))
                obs.append(len(o))
        if sum(fe.drops.values()):
            raise RuntimeError(f"frames dropped in the benchmark: {dict(fe.drops)} {fe.last_error}")
    t = np.array(times)
    return {"mean_ms": float(t.mean()), "p95_ms": float(np.percentile(t, 95)),
            "stereo_points": float(np.mean(stereo)), "observations": float(np.mean(obs))}


def middlebury_accuracy(detector: str) -> dict:
    """Accepted matches on the Middlebury motorcycle pair and the fraction within 1 px of truth."""
    from skimage import data

    left, right, truth = data.stereo_motorcycle()
    gl = cv2.cvtColor(left, cv2.COLOR_RGB2GRAY)
    gr = cv2.cvtColor(right, cv2.COLOR_RGB2GRAY)
    cfg = FrontendConfig(detector=detector, max_disparity=80)
    kps = FeatureExtractor(cfg).detect(gl, 2 * cfg.patch_radius + 1)
    m = match_stereo(gl, gr, kps.xy, cfg)
    xy = np.rint(kps.xy[m.index]).astype(np.int64)
    gt = truth[xy[:, 1], xy[:, 0]]
    known = np.isfinite(gt)
    err = np.abs(m.disparity[known] - gt[known])
    return {"detections": len(kps), "accepted": int(m.index.size), "with_truth": int(known.sum()),
            "within_1px": float(np.mean(err <= 1.0)), "median_error_px": float(np.median(err))}


def homography_pair(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The image warped by a fixed mild homography (rotation 3°, scale 1.05, shift, perspective)."""
    h, w = image.shape
    a = np.deg2rad(3.0)
    hom = np.array([[1.05 * np.cos(a), -1.05 * np.sin(a), 12.0],
                    [1.05 * np.sin(a), 1.05 * np.cos(a), -8.0],
                    [2e-5, 1e-5, 1.0]])
    return cv2.warpPerspective(image, hom, (w, h), flags=cv2.INTER_LINEAR), hom


def distinctiveness(image: np.ndarray, cfg: FrontendConfig, e0s=E0S, tol_px: float = 2.0) -> dict:
    """Fraction of correct nearest-neighbour matches with distance ≤ E0, per E0 (002 Table V).

    Keypoints are detected in both images; a keypoint of the first image is matched to the
    nearest descriptor of the second (no spatial gate); correct when within ``tol_px`` of the
    homography's image of it. Only keypoints whose true position lies inside the second image
    and that the detector found again there (a keypoint within ``tol_px``) are scored.
    """
    warped, hom = homography_pair(image)
    fx = FeatureExtractor(cfg)
    margin = 24
    a = fx.detect(image, margin)
    b = fx.detect(warped, margin)
    da, oka = fx.describe(image, a)
    db, okb = fx.describe(warped, b)
    xa, xb, da, db = a.xy[oka], b.xy[okb], da[oka], db[okb]
    proj = cv2.perspectiveTransform(xa.reshape(-1, 1, 2), hom).reshape(-1, 2)
    h, w = image.shape
    inside = (proj[:, 0] >= margin) & (proj[:, 0] < w - margin) & (proj[:, 1] >= margin) & (
        proj[:, 1] < h - margin)
    xa, da, proj = xa[inside], da[inside], proj[inside]
    # score only keypoints the detector found again: descriptor quality, not repeatability
    repeated = (np.linalg.norm(proj[:, None, :] - xb[None, :, :], axis=2) <= tol_px).any(axis=1)
    xa, da, proj = xa[repeated], da[repeated], proj[repeated]
    dist = descriptor_distance(da, db)
    j = np.argmin(dist, axis=1)
    best = dist[np.arange(len(j)), j]
    correct = np.linalg.norm(xb[j] - proj, axis=1) <= tol_px
    rows = []
    for e0 in e0s:
        sel = best <= e0
        rows.append({"E0": e0, "matches": int(sel.sum()),
                     "correct_fraction": float(correct[sel].mean()) if sel.any() else float("nan")})
    return {"keypoints": int(len(xa)), "rows": rows}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="mrslam bench frontend", description=__doc__.split("\n")[0])
    parser.add_argument("--out", default="runs/bench")
    parser.add_argument("--data", default=None, help="folder holding euroc_v101_micro")
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args(argv)
    if any(os.environ.get(v) != "1" for v in _THREAD_VARS):
        env = dict(os.environ, **{v: "1" for v in _THREAD_VARS})
        cmd = [sys.executable, "-m", "mrslam_core.bench.frontend", *(argv if argv is not None else sys.argv[1:])]
        return subprocess.run(cmd, env=env, check=False).returncode
    cv2.setNumThreads(1)
    root = Path(args.data) if args.data else data_root()
    folder = root / "euroc_v101_micro"
    if not folder.is_dir():
        print(f"no EuRoC data at {folder}", file=sys.stderr)
        return 2
    rig, pairs = cropped_rectified(folder)
    result: dict = {"image": "640x480", "pairs": len(pairs), "threads": 1, "speed": {},
                    "middlebury": {}, "distinctiveness": {}}
    print(f"frontend step, 640x480 EuRoC V1_01 pairs, {len(pairs)} pairs x {args.repeats}, 1 thread")
    for det, desc in COMBOS:
        r = time_frontend(rig, pairs, FrontendConfig(detector=det, descriptor=desc), args.repeats)
        result["speed"][f"{det}+{desc}"] = r
        print(f"  {det:6s}+{desc:5s}  mean {r['mean_ms']:6.2f} ms  p95 {r['p95_ms']:6.2f} ms  "
              f"stereo points {r['stereo_points']:5.1f}  observations {r['observations']:4.1f}")
    print("Middlebury motorcycle (skimage), accepted matches within 1 px of ground truth")
    for det in ("harris", "orb", "sift"):
        r = middlebury_accuracy(det)
        result["middlebury"][det] = r
        print(f"  {det:6s}  accepted {r['accepted']:4d}/{r['detections']:4d}  within 1 px "
              f"{100 * r['within_1px']:5.1f} %  median error {r['median_error_px']:.3f} px")
    kitti = root / "kitti_excerpt"
    if (kitti / "calib.txt").is_file():
        from mrslam_core.configio import PROFILES, load_profile
        from mrslam_core.datasets.stereo import open_sequence
        from mrslam_core.pipelines.dataset import DatasetRunConfig

        seq = open_sequence("kitti", kitti)
        profile = load_profile(DatasetRunConfig, PROFILES / "real_stereo.yaml")
        kpairs = [(*seq.read(i), int(f.stamp_ns)) for i, f in enumerate(seq.frames)]
        result["kitti"] = {"image": f"{seq.rig.width}x{seq.rig.height}", "pairs": len(kpairs), "speed": {}}
        print(f"frontend step with visual odometry, {seq.rig.width}x{seq.rig.height} KITTI pairs, real stereo "
              f"profile, {len(kpairs)} pairs x {args.repeats}, 1 thread")
        for det in ("harris", "orb", "sift"):
            desc = "usurf" if det == "harris" else det
            cfg = replace(profile.frontend, detector=det, descriptor=desc)
            r = time_frontend(seq.rig, kpairs, cfg, args.repeats)
            result["kitti"]["speed"][f"{det}+{desc}"] = r
            print(f"  {det:6s}+{desc:5s}  mean {r['mean_ms']:6.2f} ms  p95 {r['p95_ms']:6.2f} ms  "
                  f"stereo points {r['stereo_points']:5.1f}  observations {r['observations']:4.1f}")
    else:
        print(f"no KITTI excerpt at {kitti}: its timing is skipped", file=sys.stderr)
    left = pairs[0][0]
    print("descriptor distinctiveness: fraction correct (matches) vs E0, EuRoC left vs homography")
    print("  " + " ".join(f"{e:>12}" for e in ["combo"] + [f"E0={e0}" for e0 in E0S]))
    for det, desc in COMBOS:
        r = distinctiveness(left, FrontendConfig(detector=det, descriptor=desc))
        result["distinctiveness"][f"{det}+{desc}"] = r
        cells = [f"{row['correct_fraction']:.2f}({row['matches']})" for row in r["rows"]]
        print("  " + " ".join(f"{c:>12}" for c in [f"{det}+{desc}"] + cells))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "frontend.json").write_text(json.dumps(result, indent=2))
    print(f"wrote {out / 'frontend.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
