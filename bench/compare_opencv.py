#!/usr/bin/env python3
"""Compare hvs stereo matchers with OpenCV StereoBM and StereoSGBM in one run.

Benchmark tooling only: OpenCV is never used by the product. Everything runs single-threaded
(cv2.setNumThreads(1); hvs matchers are single-threaded), on the same images:

  speed:    the built-in simulated hallway pair that `hvs bench stereo --export` writes,
            at 320x240 (disparities 9..55) and 640x480 (18..110);
  accuracy: every scene of a dataset folder as `hvs eval --export` writes it (grey, and with
            --degrade the webcam-defect version too), scored by `hvs eval --predictions`,
            i.e. by exactly the same code that scores the hvs matchers.

  shifted:  with --vshift=-4,-2,2,4 the same scenes with the right image shifted by those rows
            (clean and degraded), as `hvs eval --vshift` makes them; hvs undoes the shift with
            its online row alignment, OpenCV matches the shifted pair as it is.

Usage: python3 bench/compare_opencv.py [--hvs target/release/hvs] [--dataset ../shared/datasets]
       [--vshift=-4,-2,2,4] [--skip-speed]
Installs opencv-python-headless with pip if it is missing.
"""

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def ensure_opencv():
    try:
        import cv2  # noqa: F401
    except ImportError:
        print("installing opencv-python-headless (benchmark only) ...", file=sys.stderr)
        subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "opencv-python-headless", "numpy"], check=True)
    import cv2
    import numpy as np
    cv2.setNumThreads(1)
    return cv2, np


def num_disparities(min_disp, max_disp):
    """OpenCV needs a multiple of 16 covering min_disp..max_disp."""
    n = max_disp - min_disp + 1
    return ((n + 15) // 16) * 16


def make_matchers(cv2, min_disp, max_disp):
    """OpenCV matchers with the parameters its documentation recommends."""
    num = num_disparities(min_disp, max_disp)
    out = {}
    bm = cv2.StereoBM_create(numDisparities=num, blockSize=9)
    bm.setMinDisparity(min_disp)
    bm.setUniquenessRatio(10)
    bm.setTextureThreshold(10)
    bm.setSpeckleWindowSize(100)
    bm.setSpeckleRange(2)
    bm.setDisp12MaxDiff(1)
    out["opencv-bm"] = bm
    for name, mode, bs in (("opencv-sgbm", cv2.STEREO_SGBM_MODE_SGBM, 5), ("opencv-sgbm3way", cv2.STEREO_SGBM_MODE_SGBM_3WAY, 3)):
        out[name] = cv2.StereoSGBM_create(
            minDisparity=min_disp,
            numDisparities=num,
            blockSize=bs,
            P1=8 * bs * bs,
            P2=32 * bs * bs,
            disp12MaxDiff=1,
            uniquenessRatio=10,
            speckleWindowSize=100,
            speckleRange=2,
            preFilterCap=63,
            mode=mode,
        )
    return out


def to_kitti(np, disp16, min_disp):
    """OpenCV fixed point (x16, invalid = (min_disp - 1) * 16) to KITTI (x256, 0 = invalid)."""
    d = disp16.astype(np.float64) / 16.0
    out = np.round(d * 256.0)
    out[disp16 < min_disp * 16] = 0
    out = np.clip(out, 0, 65535).astype(np.uint16)
    out[(out == 0) & (disp16 >= min_disp * 16)] = 1
    return out


def hvs_json(cmd):
    res = subprocess.run(cmd, check=True, capture_output=True, text=True)
    return json.loads(res.stdout)


def speed(args, cv2, np, workdir):
    bench_dir = workdir / "bench"
    ours = hvs_json([args.hvs, "bench", "stereo", "--algo", args.algo, "--size", "both", "--frames", str(args.frames), "--export", str(bench_dir), "--json"])
    rows = []
    for size, (min_d, max_d) in (("320x240", (9, 55)), ("640x480", (18, 110))):
        left = cv2.imread(str(bench_dir / f"left-{size}.png"), cv2.IMREAD_GRAYSCALE)
        right = cv2.imread(str(bench_dir / f"right-{size}.png"), cv2.IMREAD_GRAYSCALE)
        for name, m in make_matchers(cv2, min_d, max_d).items():
            for _ in range(3):
                m.compute(left, right)
            times = []
            for _ in range(args.frames):
                t = time.perf_counter()
                m.compute(left, right)
                times.append((time.perf_counter() - t) * 1e3)
            times.sort()
            rows.append({"algorithm": name, "size": size, "median_ms": times[len(times) // 2]})
    for r in ours:
        rows.append({"algorithm": r["algorithm"], "size": f"{r['width']}x{r['height']}", "median_ms": r["median_ms"]})
    return rows


def accuracy(args, cv2, np, workdir):
    inputs = workdir / "inputs"
    vshift = [f"--vshift={args.vshift}"] if args.vshift else []
    subprocess.run([args.hvs, "eval", "--algo", "none", "--dataset", args.dataset, "--degrade", "--export", str(inputs)] + vshift, check=True, capture_output=True)
    methods = None
    for line in (inputs / "scenes.tsv").read_text().splitlines():
        name, condition, _w, _h, min_d, max_d = line.split("\t")
        min_d, max_d = int(min_d), int(max_d)
        sub = inputs / f"{name}-{condition}"
        left = cv2.imread(str(sub / "left.png"), cv2.IMREAD_GRAYSCALE)
        right = cv2.imread(str(sub / "right.png"), cv2.IMREAD_GRAYSCALE)
        matchers = make_matchers(cv2, min_d, max_d)
        methods = list(matchers)
        for method, m in matchers.items():
            out_dir = workdir / "pred" / method
            out_dir.mkdir(parents=True, exist_ok=True)
            cv2.imwrite(str(out_dir / f"{name}-{condition}.png"), to_kitti(np, m.compute(left, right), min_d))
    rows = []
    for method in methods:
        res = hvs_json([args.hvs, "eval", "--algo", method, "--dataset", args.dataset, "--degrade", "--predictions", str(workdir / "pred" / method), "--json"] + vshift)
        rows += res["means"]
        rows_scene = res["rows"]
        for r in rows_scene:
            r["algorithm"] = method
        args.scene_rows += rows_scene
    ours = hvs_json([args.hvs, "eval", "--algo", args.algo, "--dataset", args.dataset, "--degrade", "--json", "--repeat", "1"] + vshift)
    rows += ours["means"]
    args.scene_rows += ours["rows"]
    return rows


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--hvs", default="target/release/hvs")
    p.add_argument("--dataset", default="../shared/datasets")
    p.add_argument("--algo", default="all", help="hvs algorithms (comma list or all)")
    p.add_argument("--frames", type=int, default=30)
    p.add_argument("--reference", default="opencv-sgbm", help="OpenCV method the ratios are taken against")
    p.add_argument("--json", action="store_true")
    p.add_argument("--vshift", default="", help="also score with the right image shifted by these rows, e.g. -4,-2,2,4")
    p.add_argument("--skip-speed", action="store_true", help="accuracy only")
    args = p.parse_args()
    args.scene_rows = []
    cv2, np = ensure_opencv()
    with tempfile.TemporaryDirectory() as tmp:
        workdir = Path(tmp)
        speed_rows = [] if args.skip_speed else speed(args, cv2, np, workdir)
        acc_rows = accuracy(args, cv2, np, workdir)
    if args.json:
        print(json.dumps({"speed": speed_rows, "accuracy": acc_rows, "scenes": args.scene_rows}, indent=2))
        return
    print(f"OpenCV {cv2.__version__}, single thread; hvs single thread; same images")
    print("\nspeed (simulated hallway pair), median ms per frame; ratio = reference / algorithm (>1: faster than the reference)")
    for size in ("320x240", "640x480") if speed_rows else ():
        ref = next(r["median_ms"] for r in speed_rows if r["algorithm"] == args.reference and r["size"] == size)
        for r in sorted((r for r in speed_rows if r["size"] == size), key=lambda r: r["median_ms"]):
            print(f"  {size}  {r['algorithm']:<16} {r['median_ms']:8.2f} ms   {ref / r['median_ms']:6.2f}x")
    conditions = []
    for r in acc_rows:
        if r["condition"] not in conditions:
            conditions.append(r["condition"])
    names = []
    for r in acc_rows:
        if r["algorithm"] not in names:
            names.append(r["algorithm"])
    print("\naccuracy, mean over scenes: bad-2 % (lower is better); density % in brackets")
    print(f"  {'algorithm':<16}" + "".join(f" {c:>16}" for c in conditions))
    for n in names:
        cells = []
        for c in conditions:
            r = next((r for r in acc_rows if r["algorithm"] == n and r["condition"] == c), None)
            cells.append(f"{r['bad2_pct']:7.2f} ({r['density_pct']:5.1f})" if r else f"{'-':>15}")
        print(f"  {n:<16}" + "".join(f" {x:>16}" for x in cells))
    if args.vshift:
        print("\nper scene, bad-2 %")
        scenes = []
        for r in args.scene_rows:
            if r["scene"] not in scenes:
                scenes.append(r["scene"])
        for sc in scenes:
            print(f"  {sc}")
            for n in names:
                cells = []
                for c in conditions:
                    r = next((r for r in args.scene_rows if r["algorithm"] == n and r["condition"] == c and r["scene"] == sc), None)
                    cells.append(f"{r['bad2_pct']:7.2f}" if r else "-")
                print(f"    {n:<14}" + "".join(f" {x:>16}" for x in cells))


if __name__ == "__main__":
    main()
