"""``python -m greenloop slam RECORDING --odometry FILE``: argument parsing and printing only; the work
is ``greenloop.mapping.slam.correct``."""
from __future__ import annotations

from greenloop import detect
from greenloop.mapping import posegraph, slam


def add_parser(sub) -> None:
    """The ``slam`` subcommand's arguments."""
    s = sub.add_parser("slam", help="correct a recording's odometry with its loop closures (a robust pose graph)",
                       description="Build a pose graph of the odometry (one pose per frame) and the loop "
                                   "closures, optimise it (GTSAM; default GNC with the odometry as known "
                                   "inliers), write the corrected trajectory (TUM) and each loop factor's "
                                   "final weight (CSV); print the ATE when the folder has CameraTrajectory.txt.")
    s.add_argument("recording", metavar="RECORDING",
                   help="the sequence folder (its CameraTrajectory.txt is the ground truth), a ROS bag or a video")
    s.add_argument("--odometry", required=True, metavar="FILE",
                   help="odometry: a bag with a nav_msgs/Odometry topic (the recording itself for a bag), or a TUM or "
                        "KITTI file; a folder's frames take the pose stamped with their frame number, a bag's or "
                        "video's the pose at their time (interpolated)")
    s.add_argument("--odometry-topic", default=None, metavar="TOPIC", help="the bag's Odometry topic (when it has several)")
    s.add_argument("--topic", default=None, metavar="TOPIC", help="the bag recording's camera topic (when it has several)")
    s.add_argument("--max-dt", type=float, default=0.1, metavar="S",
                   help="seconds: the farthest a frame's nearest odometry message may be (bags and videos; default 0.1)")
    s.add_argument("--closures", default=None, metavar="CSV",
                   help="loop closures: query (or frame), match, rx ry rz (rotation vector, rad), tx ty tz (m) of "
                        "T_match_query, metric (1: metric translation, 0: direction only): detect's --matches file "
                        "(rows with closure 0 or no pose are skipped); default: run detect on the recording (the "
                        "named default, verified) and use its closures with a pose")
    s.add_argument("--out", required=True, metavar="TRAJ.tum", help="the corrected trajectory to write (TUM)")
    s.add_argument("--weights", default=None, metavar="CSV",
                   help="each loop factor's final weight (default: beside --out, *_loops.csv)")
    s.add_argument("--back-end", default="gnc", choices=posegraph.METHODS,
                   help="gnc: graduated non-convexity, TLS (default); lm: plain Levenberg-Marquardt; "
                        "huber / cauchy: a robust kernel on the loop factors")
    s.add_argument("--planar", action="store_true",
                   help="a ground robot: optimise Pose2 in the odometry's plane (yaw only), keep its height, pitch, roll")
    s.set_defaults(func=run)


def run(args) -> int:
    """Correct, then say what was written and, with ground truth, the errors before and after."""
    closures = args.closures
    if closures is None:
        closures = detect.closures_of(args.recording, args.topic)
        print(f"# detect: {len(closures)} closures, {sum(c.R is not None for c in closures)} with a verified pose",
              flush=True)
    c = slam.correct(args.recording, args.odometry, args.out, closures, args.weights, args.back_end,
                     planar=args.planar, topic=args.odometry_topic, camera_topic=args.topic, max_dt=args.max_dt)
    kept = int((c.result.weights > slam.KEPT).sum())
    source = args.closures or "detect's closures"
    skipped = f" ({c.skipped} of {source} without a verified pose left out)" if c.skipped else ""
    print(f"wrote {len(c.odometry)} corrected poses to {c.out} (back end {args.back_end}: {kept} of "
          f"{len(c.loops)} loop factors kept{skipped}); loop weights to {c.weights_out}")
    if c.errors:
        o, k = c.errors["odometry"], c.errors["corrected"]
        print(f"ATE (RMSE after SE(3) alignment): odometry {o['ate_m']:.3f} m, corrected {k['ate_m']:.3f} m; "
              f"end-point error: odometry {o['end_point_m']:.3f} m, corrected {k['end_point_m']:.3f} m")
    return 0
