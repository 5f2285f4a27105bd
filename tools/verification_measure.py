"""The measurements behind greenloop.methods.verification's Rule: inliers of true and false pairs,
the size below which frames are 'too-small', pose errors and the time per verified pair.

* Gardens Point (no camera.yaml: the 60-degree default intrinsics): day_right frame k against
  day_left frame k (the same place, walked on the other side of the path: a true pair) and
  day_left frame k + 100 mod 200 (another place: a false pair), every 2nd k; at 640x360 (the day
  frames, 960x540, resized to night_right's size) per feature configuration (ORB 2000 / 3000 /
  4000 keypoints, SIFT 2000) the inliers of the model the rule picks, their share, and what the
  default rule accepts; night_right frame k against day_right frame k and k + 100 (the same side:
  an illumination change only); the day pair at its native
  960x540 and downscaled (427x240, 320x180, 240x135, 160x90) for the 'too-small' size.
* The synthetic greenhouse rendered at 640x480 (the full 2260-frame route, its end-to-start
  revisit of aisle A1): queries 2100..2149 against their nearest earlier frame +- 15 frames (a
  0.4 m baseline; true pairs, poses known) without and with the match frame's depth, and against
  frame q - 1100 (another aisle: false pairs); the pose errors against T_match^-1 T_query.
* Time per verified pair (both frames' features, matching, geometry), median over the pairs:
  the thread's CPU time (time.thread_time; the machine is shared) and the wall time.

    PYTHONPATH=. .venv/bin/python tools/verification_measure.py [--gardenspoint /work/shared/real/gardenspoint]
        [--out results/verification]

Writes pairs.csv (one row per pair and configuration) and summary.md into --out.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from greenloop.datasets.synthetic import build_scene, camera_intrinsics, render_frame, route_world  # noqa: E402
from greenloop.methods.verification import default_camera, DEFAULT_RULE, verify_pair  # noqa: E402
from greenloop import report  # noqa: E402
from greenloop.util.files import write_atomic  # noqa: E402

DEFAULT_NAME = "orb-3000 (default)"
CONFIGS = {"orb-2000": DEFAULT_RULE._replace(n_features=2000), DEFAULT_NAME: DEFAULT_RULE,
           "orb-4000": DEFAULT_RULE._replace(n_features=4000),
           "sift-2000": DEFAULT_RULE._replace(features="sift", n_features=2000)}
BASE = (640, 360)                                          # night_right's size; the day frames resized to it
SIZES = ((960, 540), (427, 240), (320, 180), (240, 135), (160, 90))    # the day pair at its native size and smaller
OPEN = dict(min_inliers=0, min_ratio=0.0, min_side=1)      # record every pair's numbers; judge after


def _timed(fq, fm, cam, rule, depth_m=None) -> dict:
    """verify_pair's numbers of one pair under ``rule`` with the acceptance opened, and its times."""
    t0, c0 = time.perf_counter(), time.thread_time()
    v = verify_pair(fq, fm, cam, depth_m=depth_m, rule=rule._replace(**OPEN))
    cpu, wall = time.thread_time() - c0, time.perf_counter() - t0
    ok = v.inliers >= rule.min_inliers and v.inlier_ratio >= rule.min_ratio
    return dict(matches=v.matches, inliers=v.inliers, ratio=v.inlier_ratio, model=v.model,
                accepted=bool(ok), cpu_ms=1000 * cpu, wall_ms=1000 * wall, v=v)


def _resized(frame, size):
    """frame resized to size (w, h) with area averaging (itself where it has that size)."""
    if frame.shape[1::-1] == tuple(size):
        return frame
    return cv2.resize(frame, size, interpolation=cv2.INTER_AREA)


def gardens_point(root: Path) -> list[dict]:
    """Rows of every Gardens Point pair: per configuration at 640x360, the night traversal, the sizes."""
    read = lambda side, k: cv2.imread(str(root / side / f"Image{k:03d}.jpg"))
    rows = []
    for k in range(0, 200, 2):
        day, night = read("day_right", k), read("night_right", k)
        for label, kk in (("loop", k), ("other place", (k + 100) % 200)):
            match = read("day_left", kk)
            q, m = _resized(day, BASE), _resized(match, BASE)
            base = dict(set="gardenspoint day", size=f"{BASE[0]}x{BASE[1]}", pair=label, k=k)
            for name, rule in CONFIGS.items():
                rows.append(dict(base, config=name, **_timed(q, m, default_camera(*BASE), rule)))
            same_side = _resized(read("day_right", kk), BASE)
            rows.append(dict(base, set="gardenspoint night", config=DEFAULT_NAME,
                             **_timed(night, same_side, default_camera(*BASE), DEFAULT_RULE)))
            for size in SIZES:
                rows.append(dict(base, size=f"{size[0]}x{size[1]}", config=DEFAULT_NAME,
                                 **_timed(_resized(day, size), _resized(match, size), default_camera(*size),
                                          DEFAULT_RULE)))
        print(f"gardens point {k + 2}/200", end="\r", flush=True)
    return rows


def greenhouse() -> list[dict]:
    """Rows of the synthetic pairs at 640x480 (module doc), with pose errors."""
    scene, (poses, _) = build_scene(0), route_world(2260, 0)
    cam = camera_intrinsics((640, 480))
    rng = np.random.default_rng(0)

    def render(i):
        bgr, depth = render_frame(scene, poses[i], (640, 480))
        return np.clip(bgr + rng.normal(0, 3, bgr.shape), 0, 255).astype(np.uint8), depth
    rows = []
    for q in range(2100, 2150):
        near = int(np.argmin(np.linalg.norm(poses[:400, :3, 3] - poses[q, :3, 3], axis=1)))
        fq, _ = render(q)
        loop = near - 15 if q % 2 and near >= 15 else near + 15          # 0.4 m behind or ahead
        for label, m in (("loop", loop), ("neighbour aisle", q - 1100),
                         ("other place", q - 600)):
            frame, depth = render(m)
            T = np.linalg.inv(poses[m]) @ poses[q]
            for with_depth in (False, True):
                r = _timed(fq, frame, cam, DEFAULT_RULE, depth if with_depth else None)
                rows.append(dict(set="greenhouse" + (" rgb-d" if with_depth else ""), config=DEFAULT_NAME,
                                 size="640x480", pair=label, k=q, distance_m=np.linalg.norm(T[:3, 3]),
                                 **r, **_pose_errors(r["v"], T)))
        print(f"greenhouse {q - 2099}/50", end="\r", flush=True)
    return rows


def _pose_errors(v, T) -> dict:
    """Rotation error (deg), translation direction error (deg), metric error (m, nan unless
    metric), and pose_ok: rotation <= 2 deg and metric <= 0.3 m (direction <= 10 deg without depth)."""
    if v.R is None:
        return dict(rot_deg=np.nan, dir_deg=np.nan, metric_m=np.nan, pose_ok=False)
    t = T[:3, 3]
    cos = v.t @ t / max(np.linalg.norm(v.t) * np.linalg.norm(t), 1e-12)
    rot = np.degrees(Rotation.from_matrix(v.R @ T[:3, :3].T).magnitude())
    direction = np.degrees(np.arccos(np.clip(cos, -1, 1)))
    metric = np.linalg.norm(v.t - t) if v.metric else np.nan
    ok = rot <= 2.0 and (metric <= 0.3 if v.metric else direction <= 10.0)
    return dict(rot_deg=rot, dir_deg=direction, metric_m=metric, pose_ok=bool(ok))


def _pct(x) -> str:
    """'p5 / median / p95 (max)' of x."""
    x = np.asarray(x, float)
    return f"{np.percentile(x, 5):.0f} / {np.median(x):.0f} / {np.percentile(x, 95):.0f} ({x.max():.0f})"


def summary(df: pd.DataFrame) -> str:
    """summary.md: per (set, config, size, pair kind) the inliers, what the default rule accepts,
    the accepted pairs' poses where known, and the time per pair."""
    prov = report.provenance()
    lines = ["# Verification: inliers of loop and other pairs, the default rule, time per pair", "",
             f"Default rule: {DEFAULT_RULE}.", "",
             "Written by tools/verification_measure.py (its docstring says which pairs). Inliers: "
             "p5 / median / p95 (max) of the model the rule picks; ratio: their share of the points "
             "fitted (median); accepted: by the default rule; wrong pose: accepted pairs whose pose "
             "misses rotation <= 2 deg and translation <= 0.3 m (direction <= 10 deg without depth); "
             "ms: median per pair (both frames' features, matching, geometry), CPU time of the thread "
             f"and wall time on {prov['cpu']}, nothing else computing; commit {str(prov['git_commit'])[:12]}"
             f"{' (dirty)' if prov.get('git_dirty') else ''}, environment {str(prov['environment_hash'])[:12]}, "
             f"{prov['date']}.", "",
             "| set | config | size | pairs | kind | inliers | ratio | accepted | wrong pose | ms cpu / wall |",
             "|" + "---|" * 10]
    for (s, c, z, p), g in df.groupby(["set", "config", "size", "pair"], sort=False):
        acc = g[g.accepted]
        wrong = f"{(~acc.pose_ok.astype(bool)).sum()} of {len(acc)}" if "pose_ok" in g and g.pose_ok.notna().all() else "-"
        lines.append(f"| {s} | {c} | {z} | {len(g)} | {p} | {_pct(g.inliers)} | {g.ratio.median():.2f} | "
                     f"{g.accepted.mean():.0%} | {wrong} | {g.cpu_ms.median():.0f} / {g.wall_ms.median():.0f} |")
    pose = df[df.set.str.startswith("greenhouse") & (df.pair == "loop") & df.accepted]
    lines += ["", "Pose errors of the accepted greenhouse loop pairs against T_match^-1 T_query "
              "(median / p95): rotation deg, translation direction deg, metric translation m.", "",
              "| set | pairs | rotation | direction | metric | models |", "|---|---|---|---|---|---|"]
    for s, g in pose.groupby("set", sort=False):
        fmt = lambda x: f"{np.nanmedian(x):.2f} / {np.nanpercentile(x, 95):.2f}" if np.isfinite(x).any() else "-"
        models = ", ".join(f"{m} {n}" for m, n in g.model.value_counts().items())
        lines.append(f"| {s} | {len(g)} | {fmt(g.rot_deg)} | {fmt(g.dir_deg)} | {fmt(g.metric_m)} | {models} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gardenspoint", type=Path, default=Path("/work/shared/real/gardenspoint"))
    ap.add_argument("--out", type=Path, default=Path("results/verification"))
    args = ap.parse_args(argv)
    if not (args.gardenspoint / "day_left").is_dir():
        raise FileNotFoundError(f"no Gardens Point at {args.gardenspoint}: pass --gardenspoint FOLDER "
                                f"(day_left/, day_right/, night_right/)")
    cv2.setNumThreads(1)
    df = pd.DataFrame(greenhouse() + gardens_point(args.gardenspoint)).drop(columns="v")
    write_atomic(args.out / "pairs.csv", df.to_csv(index=False, float_format="%.4g"))
    write_atomic(args.out / "summary.md", summary(df))
    print(summary(df))
    return 0


if __name__ == "__main__":
    sys.exit(main())
