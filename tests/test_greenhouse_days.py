"""The greenhouse over days: the larger hall, its days, odometry, ground truth, CLI.

Tiny parameters throughout (a two-aisle hall, two days, 160x120 frames every 0.25 m), and the
guard that the single-day sequence the main paper rests on renders byte for byte as before.
"""
from __future__ import annotations

import dataclasses
import filecmp
import hashlib
import json

import cv2
import numpy as np
import pytest

from greenloop import groundtruth
from greenloop.cli import main as cli_main
from greenloop.datasets import odometry, sequence
from greenloop.datasets.synthetic import daysmake, make_greenhouse
from greenloop.datasets.synthetic.days import day_route, design_days, TINY_HALL
from greenloop.datasets.synthetic.dayscene import build_day_scene
from greenloop.datasets.synthetic.render import _grid, render_frame
from greenloop.datasets.synthetic.route import route, route_world
from greenloop.datasets.synthetic.scene import build_scene
from greenloop.datasets.synthetic.sensor import _sensor

# sha256 of frames 0, 77, 150, 199 (colour and depth bytes) of the 200-frame 160x120 seed-0
# sequence and of its poses rounded to 1e-9, computed from the code before the days existed
SINGLE_DAY_FRAMES = "04650c8272bc22e44593bafc293b24d1e964d2ae52b8ee4d2f0b9c9ac3e291c5"
SINGLE_DAY_POSES = "f1ac80a5730d8d3e6e2ded48af83b4d404ba1bd55e967c2e01a8493c0ed39e68"
# sha256 of the same frames' decoded rgb/ and depth/ PNGs and CameraTrajectory.txt as
# make_greenhouse writes them (200 frames, 160x120, seed 0), from the code before the days
SINGLE_DAY_FOLDER = "5b66429b2113221732c1c4361b68f2a8f0a2fcbf3694bdedae44cba8f1a53f49"


def test_single_day_sequence_unchanged():
    size, n = (160, 120), 200
    scene, g = build_scene(0), _grid(size)
    poses, s = route_world(n, 0)
    h = hashlib.sha256()
    for i in (0, 77, 150, 199):
        img, depth = render_frame(scene, poses[i], size, g)
        bgr, d16 = _sensor(scene, img, depth, float(s[i]), g, np.random.default_rng([0, i, 0xF4A3E]), 0.0)
        h.update(bgr.tobytes())
        h.update(d16.tobytes())
    assert h.hexdigest() == SINGLE_DAY_FRAMES
    assert hashlib.sha256(np.round(route(n, 0), 9).tobytes()).hexdigest() == SINGLE_DAY_POSES


def test_single_day_folder_unchanged(tmp_path):
    out = make_greenhouse(tmp_path / "s", 200, (160, 120), 0, progress=False, workers=1)
    h = hashlib.sha256()
    for i in (0, 77, 150, 199):
        h.update(cv2.imread(str(out / "rgb" / f"{i}.png"), cv2.IMREAD_UNCHANGED).tobytes())
        h.update(cv2.imread(str(out / "depth" / f"{i}.png"), cv2.IMREAD_UNCHANGED).tobytes())
    h.update((out / "CameraTrajectory.txt").read_bytes())
    assert h.hexdigest() == SINGLE_DAY_FOLDER


# ------------------------------------------------------------------------------ the days
@pytest.fixture(scope="module")
def tiny_days(tmp_path_factory):
    """The tiny two-day hall rendered in this process: (folder, hall, days, poses, to_world)."""
    out = tmp_path_factory.mktemp("days") / "tiny"
    daysmake.make_greenhouse_days(out, n_days=2, tiny=True, workers=1, progress=False)
    hall, days, poses, _, to_world = daysmake.build_days(2, tiny=True)
    return out, hall, days, poses, to_world


def _nearest(poses, to_world, x, z) -> int:
    """Index of the pose (N, 4, 4) world frame whose camera stands nearest hall point (x, z)."""
    t = (np.linalg.inv(to_world)[None] @ poses)[:, :3, 3]
    return int(np.argmin(np.hypot(t[:, 0] - x, t[:, 2] - z)))


def _stream_gt(folder):
    """(poses (N, 4, 4), ground truth (N, N) by the pose rule at the folder's exclude)."""
    _, poses = sequence.read_trajectory(folder)
    return poses, groundtruth.loop_matrix(poses, 0.5, sequence.open(folder).exclude)


def test_stream_lists_the_days_as_traversals(tiny_days):
    out, _, days, poses, _ = tiny_days
    seq = sequence.open(out)
    assert [t.name for t in seq.traversals] == [d.name for d in days]
    assert [(t.start, t.stop) for t in seq.traversals] == [(0, len(poses[0])), (len(poses[0]), len(poses[0]) + len(poses[1]))]
    assert seq.n_frames == len(poses[0]) + len(poses[1]) and seq.has_depth and seq.has_camera
    # the paper's 150-frame window (~4.1 m) and the leaderboard's every 4th frame (~0.11 m) at 0.25 m
    assert seq.exclude == round(daysmake.EXCLUDE_M / 0.25) == 16 and seq.frame_step == 1
    _, stream = sequence.read_trajectory(out)
    assert np.allclose(stream[0], np.eye(4), atol=1e-8)            # day-00's first camera is the world
    for k, d in enumerate(days):
        _, own = sequence.read_trajectory(out / "days" / d.name)
        start = seq.traversals[k].start
        assert np.allclose(own, stream[start:start + len(own)], atol=1e-8)   # one world frame
        assert filecmp.cmp(out / "days" / d.name / "rgb" / "3.png", out / "rgb" / f"{start + 3}.png", shallow=False)


def test_planted_revisit_same_aisle_both_days(tiny_days):
    out, hall, days, _, to_world = tiny_days
    assert days[0].route[0] == days[1].route[0] == (0, 1)              # aisle 0 driven +z both days
    poses, gt = _stream_gt(out)
    n0 = sequence.open(out).traversals[1].start
    mid = (float(hall.aisle_x[0]), hall.bed_z0 + hall.bed_length / 2)
    a, b = _nearest(poses[:n0], to_world, *mid), n0 + _nearest(poses[n0:], to_world, *mid)
    assert gt[a, b] and gt[b, a]
    rel = groundtruth.relative_poses(poses, np.array([[a, b]]))[0]
    assert np.linalg.norm(rel[:3, 3]) < 0.15 and np.allclose(rel, np.linalg.inv(poses[a]) @ poses[b])
    # the revisit is found by the rule all along the aisle, not at one frame only
    assert gt[:n0, n0:].any(0).sum() >= 8


def test_opposite_direction_revisit_is_excluded_by_the_pose_rule(tiny_days):
    """Eq. 5 < 0.5 allows at most 20.4 degrees between the views (2 sqrt 2 |sin(theta / 2)| < 0.5,
    at zero distance); an opposite-direction revisit (~180 degrees, rotation term 2.83) is never
    a loop by it, however close the cameras stand; the metric rule (30 degrees) excludes it too."""
    out, hall, days, _, to_world = tiny_days
    assert (1, -1) in days[0].route and (1, 1) in days[1].route       # aisle 1 driven both ways
    poses, gt = _stream_gt(out)
    n0 = sequence.open(out).traversals[1].start
    mid = (float(hall.aisle_x[1]), hall.bed_z0 + hall.bed_length / 2)
    a, b = _nearest(poses[:n0], to_world, *mid), n0 + _nearest(poses[n0:], to_world, *mid)
    rel = groundtruth.relative_poses(poses, np.array([[a, b]]))
    _, angle = groundtruth.relative_pose_error(rel, np.eye(4)[None])
    assert np.linalg.norm(rel[0, :3, 3]) < 0.15 and angle[0] > 165
    assert not gt[a, b]
    assert not groundtruth.loop_matrix_metric(poses, 1.0, 30.0, sequence.open(out).exclude)[a, b]
    cross = poses[:n0, :3, 2] @ poses[n0:, :3, 2].T                    # cos of the viewing angle
    assert not gt[:n0, n0:][cross < np.cos(np.radians(20.5))].any()


def test_relative_pose_error_scores_an_estimate():
    T = np.tile(np.eye(4), (2, 1, 1))
    T[1, :3, 3] = [1.0, 0.0, 2.0]
    true = groundtruth.relative_poses(T, np.array([[0, 1]]))
    est = true.copy()
    c, s = np.cos(np.radians(5)), np.sin(np.radians(5))
    est[0, :3, :3] = est[0, :3, :3] @ np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    est[0, :3, 3] += [0.3, 0.0, 0.4]
    t_err, r_err = groundtruth.relative_pose_error(est, true)
    assert t_err[0] == pytest.approx(0.5) and r_err[0] == pytest.approx(5.0)
    with pytest.raises(ValueError, match="pairs must be"):
        groundtruth.relative_poses(T, np.array([[0, 2]]))


def _line(length: float, step: float = 0.05) -> np.ndarray:
    """A straight drive along +x: (N, 3) (x, z, yaw) metres and radians."""
    x = np.arange(0.0, length + 1e-9, step)
    return np.stack([x, np.zeros_like(x), np.zeros_like(x)], 1)


def test_odometry_drift_is_as_stated():
    p = _line(20.0)
    assert np.allclose(odometry.simulate_odometry(p, 3, 0, 0, 0, 0), p)          # no drift: the truth
    bias = odometry.simulate_odometry(p, 3, scale_error=0.0, slip=0.0, heading_bias=0.005, heading_noise=0.0)
    assert bias[-1, 2] == pytest.approx(0.005 * 20.0)                              # heading: bias x distance
    assert bias[-1, 1] == pytest.approx(0.005 * 20.0 ** 2 / 2, rel=0.03)           # sideways: ~ b L^2 / 2
    scale = odometry.simulate_odometry(p, 3, scale_error=0.01, slip=0.0, heading_bias=0.0, heading_noise=0.0)
    assert scale[-1, 0] == pytest.approx(20.0 * 1.01)
    # with every term on, the end-point drift grows with the distance driven (mean over seeds)
    long = _line(40.0)
    drift = np.array([[np.hypot(*(odometry.simulate_odometry(long, s)[k, :2] - long[k, :2])) for k in (200, 400, 800)]
                      for s in range(8)]).mean(0)
    assert drift[0] < drift[1] < drift[2]
    same = odometry.simulate_odometry(long, 5)
    assert np.array_equal(same, odometry.simulate_odometry(long, 5))
    assert not np.array_equal(same, odometry.simulate_odometry(long, 6))
    with pytest.raises(ValueError, match="planar must be"):
        odometry.simulate_odometry(np.zeros((4, 2)))


def test_days_odometry_starts_true_and_drifts(tiny_days):
    out, _, days, _, to_world = tiny_days
    hall = np.linalg.inv(to_world)[None]
    for d in days:
        _, true = sequence.read_trajectory(out / "days" / d.name)
        _, odo = sequence.read_trajectory(out / "days" / d.name / "odometry.txt")
        err = np.hypot(*((hall @ odo)[:, :3, 3] - (hall @ true)[:, :3, 3])[:, [0, 2]].T)   # on the floor
        assert err[0] < 1e-6 and err[-1] > 0.02 and err[-1] > err[len(err) // 4]


def test_same_seed_same_bytes_any_worker_count(tiny_days, tmp_path):
    out = tiny_days[0]
    again = daysmake.make_greenhouse_days(tmp_path / "again", n_days=2, tiny=True, workers=2, progress=False)
    files = sorted(p.relative_to(out) for p in out.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(again) for p in again.rglob("*") if p.is_file())
    assert all(filecmp.cmp(out / f, again / f, shallow=False) for f in files)
    other = daysmake.build_days(2, tiny=True, seed=1)[2]
    assert not np.allclose(other[1], tiny_days[3][1])                  # another seed, other jitter


def _render(day, pose, plants=True):
    """A clean 160x120 frame of the tiny hall on ``day`` from hall-frame ``pose`` (4, 4); without
    plants when ``plants`` is False (every bed harvested)."""
    if not plants:
        day = dataclasses.replace(day, harvested=tuple(range(TINY_HALL.n_aisles + 1)))
    return render_frame(build_day_scene(day, TINY_HALL, 0), pose, (160, 120))[0].astype(np.float64)


def test_the_days_differ_in_light_and_growth(tiny_days):
    _, hall, _, poses, to_world = tiny_days
    design = design_days(5, TINY_HALL)
    assert [d.light for d in design] == ["sun", "overcast", "night", "sun", "sun"]
    pose = np.linalg.inv(to_world) @ poses[0][_nearest(poses[0], to_world, float(hall.aisle_x[0]), hall.bed_z0 + 0.5)]
    sun, night = _render(design[0], pose), _render(design[2], pose)
    assert night.mean() < 0.35 * sun.mean()
    young, grown = (dataclasses.replace(design[0], growth=g) for g in (0.45, 1.17))
    empty = _render(young, pose, plants=False)
    leaf_px = [(np.abs(_render(d, pose) - empty).sum(2) > 30).sum() for d in (young, grown)]
    assert 0 < leaf_px[0] < 0.8 * leaf_px[1]


def test_design_of_five_days():
    days = design_days(5)
    assert len({(d.light, d.sun_azimuth) for d in days}) == 5 and "night" in [d.light for d in days]
    assert [d.offset_days for d in days] == sorted({d.offset_days for d in days})
    assert any(d.harvested for d in days) and days[-1].growth > days[0].growth
    first = dict(days[0].route)
    assert any(dict(d.route)[a] != first[a] for d in days[1:] for a in first)       # some aisles reversed
    assert len({tuple(a for a, _ in d.route) for d in days}) >= 3                    # not always one order
    assert days[0].objects != days[1].objects                                       # carts and crates moved
    with pytest.raises(ValueError, match="n_days"):
        design_days(0)


def test_cli_renders_then_reuses_the_cache(tiny_days, tmp_path, capsys):
    out = tmp_path / "cli"
    assert cli_main(["data", "greenhouse-days", str(out), "--tiny", "--days", "1", "--workers", "1", "--quiet"]) == 0
    assert "wrote 1 days" in capsys.readouterr().out
    meta = json.loads((out / daysmake.META).read_text())
    assert meta["days"][0]["name"] == "day-00" and meta["odometry"]["heading_bias_rad_per_m"] == odometry.HEADING_BIAS
    assert cli_main(["data", "greenhouse-days", str(out), "--tiny", "--days", "1", "--quiet"]) == 0
    assert "up to date" in capsys.readouterr().out
    assert not list(tmp_path.glob(".cli.tmp-*"))


def test_bad_hall_and_route_raise_value_error():
    with pytest.raises(ValueError, match="n_aisles"):
        dataclasses.replace(TINY_HALL, n_aisles=0)
    with pytest.raises(ValueError, match="hall too small"):
        dataclasses.replace(TINY_HALL, bed_length=1.0)
    day = design_days(1, TINY_HALL)[0]
    with pytest.raises(ValueError, match="route step"):
        day_route(dataclasses.replace(day, route=((5, 1),)), TINY_HALL, 0.25)
    with pytest.raises(ValueError, match="spacing"):
        daysmake.make_greenhouse_days("/nonexistent/x", n_days=1, tiny=True, spacing=0.0)
