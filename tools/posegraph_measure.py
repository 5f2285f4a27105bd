"""Time and memory of the pose graph at a recording's scale (the target: ``slam`` on 10,000
frames within 2 minutes on 2 cores, memory stated).

A 10,000-pose route (laps around a rectangle, ``trajectory.rectangle_route``), its odometry drifted
by ``trajectory.drift_poses`` (datasets.odometry's model, heading bias 0.001 rad/m), ~200 true loops between laps (pairs of poses within 0.5 m
and more than one lap's 80 % apart, ``posegraph.loops_from_poses``), optionally with false loops
(``posegraph.inject_false_loops``). Each back end runs in its own process (so that its peak
resident memory is its own): the seconds to build and optimise, the peak RSS, the ATE before and
after and the loops kept (weight > 0.5).

    OMP_NUM_THREADS=1 PYTHONPATH=. .venv/bin/python tools/posegraph_measure.py [--poses 10000]
        [--loops 200] [--false 0.2] [--methods lm gnc] [--planar]

Numbers printed, not written: results/ holds the committed tables only.
"""
from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import resource
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from greenloop.mapping import metrics, posegraph, trajectory  # noqa: E402


def problem(n_poses: int, n_loops: int, false: float, seed: int = 0):
    """(ground truth (N, 4, 4), odometry (N, 4, 4), loops, is_false) of the measured case."""
    laps = 5
    step = 2 * (40 + 10) * laps / n_poses
    gt = trajectory.rectangle_route(10, 40, step, laps)
    odo = trajectory.drift_poses(gt, seed, heading_bias=0.001)
    lap = len(gt) // laps
    pairs = cKDTree(gt[:, :3, 3]).query_pairs(0.5, output_type="ndarray")
    pairs = pairs[np.abs(pairs[:, 0] - pairs[:, 1]) > 0.8 * lap]
    rng = np.random.default_rng(seed)
    pick = pairs[rng.choice(len(pairs), size=min(n_loops, len(pairs)), replace=False)]
    loops = posegraph.loops_from_poses(gt, np.sort(pick, axis=1)[:, ::-1])
    loops, is_false = posegraph.inject_false_loops(loops, len(gt), false, seed, positions=gt[:, :3, 3])
    return gt, odo, loops, is_false


def measure(args_method):
    """One back end on the case, in this process: a dict of its numbers."""
    (n_poses, n_loops, false, planar), method = args_method
    gt, odo, loops, is_false = problem(n_poses, n_loops, false)
    t0 = time.perf_counter()
    r = posegraph.optimize(odo, loops, method, planar=planar)
    seconds = time.perf_counter() - t0
    kept = r.weights > 0.5
    return dict(method=method + (" Pose2" if planar else " Pose3"), poses=len(gt), loops=len(loops), false_loops=int(is_false.sum()),
                seconds=round(seconds, 2), peak_rss_mib=round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
                ate_odometry_m=round(metrics.ate(gt, odo), 3), ate_m=round(metrics.ate(gt, r.poses), 3),
                true_kept=int((kept & ~is_false).sum()), false_kept=int((kept & is_false).sum()))


def main() -> None:
    """Measure each back end of --methods in a fresh process; one JSON line each."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=10000)
    ap.add_argument("--loops", type=int, default=200)
    ap.add_argument("--false", type=float, default=0.0, help="fraction of false loops among the loop factors")
    ap.add_argument("--methods", nargs="+", default=["lm", "gnc"])
    ap.add_argument("--planar", action="store_true", help="Pose2 instead of Pose3")
    a = ap.parse_args()
    ctx = mp.get_context("spawn")
    for method in a.methods:
        with ctx.Pool(1, maxtasksperchild=1) as pool:
            print(json.dumps(pool.map(measure, [((a.poses, a.loops, a.false, a.planar), method)])[0]), flush=True)


if __name__ == "__main__":
    main()
