"""Tests of greenloop.datasets.synthetic: the embedded synthetic GreenHouse sequence (small and fast)."""
import json
import math

import numpy as np
import pytest

from greenloop import groundtruth
from greenloop.datasets import sequence, synthetic

from greenloop.datasets.synthetic.render import _grid
from greenloop.datasets.synthetic.sensor import _sensor
from greenloop.cli import main as cli_main

N, SIZE = 200, (160, 120)


def exclude_for(n: int) -> int:
    """The Qi 2024 neighbour exclusion (150 of 2260 frames) scaled to n frames, at least 10."""
    return max(10, round(150 * n / 2260))


def loop_groups(n: int):
    """(end-to-start pairs, mid-sequence pairs) of the route's ground truth at 0.5 / scaled exclude."""
    pairs = groundtruth.loop_pairs(groundtruth.loop_matrix(synthetic.route(n), 0.5, exclude_for(n)))
    i, j = pairs[:, 0], pairs[:, 1]
    end_start = pairs[(i < 0.1 * n) & (j > 0.9 * n)]
    middle = pairs[(i > 0.15 * n) & (j < 0.9 * n)]
    return end_start, middle


# ------------------------------------------------------------------------------------ route
@pytest.mark.parametrize("n", [200, 333, 2260])
def test_route_closes_its_loop_and_repeats_an_aisle(n):
    end_start, middle = loop_groups(n)
    assert len(end_start) > 0, "the end of the route must revisit its start"
    assert len(middle) > 0, "an aisle driven twice in the same direction must give mid-run loops"
    # the revisit: the last ~8% of frames return to the first ones, like frames 2068-2260 -> 0-138
    assert end_start[:, 1].min() < 0.95 * n and end_start[:, 0].max() > 0.04 * n
    if n == 2260:
        assert len(end_start) > 1000 and len(middle) > 5000


def test_route_is_the_same_path_for_any_frame_count():
    fine, s_fine = synthetic.route_world(2260)
    coarse, s_coarse = synthetic.route_world(200)
    assert s_fine[-1] == pytest.approx(s_coarse[-1])
    assert 58 < groundtruth.path_length(synthetic.route(2260)) < 64   # the real set: 62 m
    # every coarse pose lies on the fine path (within the jitter), same heading
    d = np.linalg.norm(coarse[:, None, :3, 3] - fine[None, :, :3, 3], axis=2)
    k = d.argmin(1)
    assert d.min(1).max() < 0.03
    assert np.all(np.einsum("ij,ij->i", coarse[:, :3, 2], fine[k, :3, 2]) > 0.99)


def test_route_poses_are_rigid_smooth_and_at_camera_height():
    poses, s = synthetic.route_world(2260)
    R = poses[:, :3, :3]
    assert np.allclose(R @ R.transpose(0, 2, 1), np.eye(3), atol=1e-9)
    assert np.allclose(np.linalg.det(R), 1.0)
    height = poses[:, 1, 3]
    assert 0.6 <= height.min() and height.max() <= 1.0
    step = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)
    assert 0.02 < step.min() and step.max() < 0.035 and abs(step.mean() - 0.027) < 0.002
    cos = np.einsum("ij,ij->i", R[1:, :, 2], R[:-1, :, 2])
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 3.0     # no jumps in heading
    look = R[:, 1, 2]                                                  # optical axis, y component
    assert np.all(look < 0.05) and np.median(look) < 0                 # level or slightly down
    rel = synthetic.route(2260)
    assert np.allclose(rel[0], np.eye(4))


def test_route_jitter_depends_on_seed_only():
    a, b = synthetic.route(300, seed=0), synthetic.route(300, seed=0)
    assert np.array_equal(a, b)
    (wa, _), (wc, _) = synthetic.route_world(300, seed=0), synthetic.route_world(300, seed=1)
    diff = np.linalg.norm(wa[:, :3, 3] - wc[:, :3, 3], axis=1)    # in the hall frame
    assert 0 < diff.max() < 0.15


# ---------------------------------------------------------------------------- the folder
def test_layout_and_camera_file(tiny_sequence):
    folder = tiny_sequence
    assert len(list((folder / "rgb").glob("*.png"))) == N
    assert len(list((folder / "depth").glob("*.png"))) == N
    lines = (folder / "CameraTrajectory.txt").read_text().splitlines()
    assert len(lines) == N and lines[0].split()[0] == "0.000000"
    assert lines[-1].split()[0] == f"{N - 1}.000000"
    cam = sequence.read_camera(folder)
    assert (cam["width"], cam["height"]) == SIZE
    assert cam["fx"] == pytest.approx(602.897 / 4) and cam["fy"] == pytest.approx(602.837 / 4)
    assert cam["cx"] == pytest.approx(328.28 / 4) and cam["cy"] == pytest.approx(241.4 / 4)
    assert cam["depth_scale"] == 5000.0
    meta = json.loads((folder / "synthetic.json").read_text())
    assert meta["n_frames"] == N and (meta["width"], meta["height"]) == SIZE and meta["seed"] == 0
    assert sequence.folder_info(folder)["kind"] == "synthetic"
    assert not list(folder.parent.glob(".*tmp*")), "temporary folder left behind"


def test_frames_load_and_poses_match(tiny_sequence):
    X = sequence.load_frames(tiny_sequence, progress=False)
    assert X.shape == (N, 32, 32, 1) and X.dtype == np.float32
    assert 0.15 < X.mean() < 0.85 and X.std() > 0.05
    rgb = sequence.load_frames(tiny_sequence, size=None, gray=False, limit=3, dtype=np.uint8)
    assert rgb.shape == (3, SIZE[1], SIZE[0], 3)
    ids, poses = sequence.read_trajectory(tiny_sequence, n_frames=N)
    assert np.array_equal(ids, np.arange(N))
    assert np.allclose(poses, synthetic.route(N, seed=0), atol=1e-6)


def test_depth_is_in_plausible_metres(tiny_sequence):
    D = sequence.load_depth(tiny_sequence)
    assert D.shape == (N, SIZE[1], SIZE[0])
    valid = D > 0
    assert 0.6 < valid.mean() < 1.0                      # holes: beyond 10 m, occlusion edges
    assert D[valid].min() >= synthetic.MIN_DEPTH and D.max() <= synthetic.MAX_DEPTH
    assert 1.0 < np.median(D[valid]) < 6.0
    # the bottom rows see the floor or bed sides close by, the image centre looks down the aisle
    assert np.median(D[:, -5:][valid[:, -5:]]) < np.median(D[:, 55:65, 70:90][valid[:, 55:65, 70:90]])


def test_images_are_a_coherent_sequence_with_a_revisit(tiny_sequence):
    X = sequence.load_frames(tiny_sequence, progress=False)[..., 0].reshape(N, -1)
    step = np.abs(np.diff(X, axis=0)).mean(1)
    far = np.abs(X[:-60] - X[60:]).mean(1)
    assert np.median(step) < 0.5 * np.median(far)
    # frame 0 looks like the frame that revisits it at the end, unlike the frames between
    err = groundtruth.pose_error(synthetic.route(N))[0]
    j = N - 30 + int(np.argmin(err[N - 30:]))
    assert err[j] < 0.5
    d0 = np.abs(X - X[0]).mean(1)
    middle = d0[exclude_for(N):N - 30]
    assert d0[j] < np.percentile(middle, 10)


# ------------------------------------------------------------------------ determinism
def test_same_seed_same_bytes_any_worker_count_other_seed_differs(tiny_sequence, tmp_path):
    again = synthetic.make_greenhouse(tmp_path / "again", N, SIZE, seed=0, progress=False, workers=1)
    other = synthetic.make_greenhouse(tmp_path / "other", N, SIZE, seed=1, progress=False, workers=2)
    for name in ("rgb/0.png", "rgb/77.png", "rgb/199.png", "depth/0.png", "depth/150.png",
                 "CameraTrajectory.txt", "camera.yaml", "synthetic.json"):
        assert (tiny_sequence / name).read_bytes() == (again / name).read_bytes(), name
    for name in ("rgb/0.png", "rgb/77.png", "depth/150.png", "CameraTrajectory.txt"):
        assert (tiny_sequence / name).read_bytes() != (other / name).read_bytes(), name
    # a different seed is the same greenhouse and route; details, jitter and lighting change
    a = sequence.load_frames(tiny_sequence, progress=False)[..., 0]
    b = sequence.load_frames(other, progress=False)[..., 0]
    assert np.abs(a - b).mean() < 0.8 * np.abs(a[:-60] - a[60:]).mean()


def test_render_frame_clean_outputs():
    scene = synthetic.build_scene(0)
    poses, _ = synthetic.route_world(200)
    img, depth = synthetic.render_frame(scene, poses[0], SIZE)
    assert img.shape == (120, 160, 3) and img.dtype == np.uint8
    assert depth.shape == (120, 160) and np.all(np.isfinite(depth)) and depth.min() > 0.1
    assert img.std() > 20            # structure, not a blank frame


def test_noise_option_changes_pixels_not_structure():
    scene = synthetic.build_scene(0)
    poses, s = synthetic.route_world(200)
    img, depth = synthetic.render_frame(scene, poses[10], SIZE)
    grid = _grid(SIZE)
    outs = [_sensor(scene, img, depth, float(s[10]), grid, np.random.default_rng(5), noise)
            for noise in (0.0, 0.0, 2.0)]
    assert np.array_equal(outs[0][0], outs[1][0]) and np.array_equal(outs[0][1], outs[1][1])
    diff = np.abs(outs[0][0].astype(float) - outs[2][0])
    assert 0.5 < diff.mean() < 4


# ------------------------------------------------------------------------------ errors
@pytest.mark.parametrize("kwargs, match", [
    ({"n_frames": 199}, "n_frames >= 200"),
    ({"n_frames": 250.5}, "integer"),
    ({"size": (159, 120)}, "at least 160x120"),
    ({"size": (640,)}, "width, height"),
    ({"seed": -1}, "non-negative"),
    ({"workers": 0}, "workers"),
    ({"noise": -1}, "noise"),
])
def test_bad_arguments_raise_value_error(tmp_path, kwargs, match):
    with pytest.raises(ValueError, match=match):
        synthetic.make_greenhouse(tmp_path / "x", **{"progress": False, **kwargs})
    assert not (tmp_path / "x").exists()


def test_existing_folder_needs_overwrite(tmp_path):
    out = tmp_path / "seq"
    out.mkdir()
    (out / "keep.txt").write_text("user data")
    with pytest.raises(FileExistsError, match="overwrite=True"):
        synthetic.make_greenhouse(out, N, SIZE, progress=False)
    assert (out / "keep.txt").read_text() == "user data"
    synthetic.make_greenhouse(out, N, SIZE, progress=False, overwrite=True, workers=1)
    assert not (out / "keep.txt").exists() and len(sequence.list_frames(out)) == N
    assert sorted(p.name for p in tmp_path.iterdir()) == ["seq"]


def test_cli_reports_bad_arguments(tmp_path, capsys):
    assert cli_main(["data", "synthetic", str(tmp_path / "x"), "--frames", "50", "--quiet"]) == 2
    assert "n_frames >= 200" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        cli_main(["data", "synthetic", str(tmp_path / "x"), "--size", "640by480"])


def test_camera_intrinsics_scale_linearly():
    k = synthetic.camera_intrinsics((320, 240))
    assert k["fx"] == pytest.approx(602.897 / 2) and k["cy"] == pytest.approx(241.4 / 2)
    assert math.isclose(k["fx"] / k["fy"], 602.897 / 602.837)
