import time

import numpy as np
import pytest

from greenloop import groundtruth
from greenloop.datasets import sequence


def _line_poses(n, step=0.1):
    P = np.tile(np.eye(4), (n, 1, 1))
    P[:, 0, 3] = np.arange(n) * step
    return P


def test_pose_error_matches_definition():
    from scipy.spatial.transform import Rotation
    rng = np.random.default_rng(0)
    P = np.tile(np.eye(4), (6, 1, 1))
    P[:, :3, :3] = Rotation.random(6, random_state=0).as_matrix()
    P[:, :3, 3] = rng.normal(size=(6, 3))
    E = groundtruth.pose_error(P)
    for i in range(6):
        for j in range(6):
            ref = np.linalg.norm(np.linalg.inv(P[i]) @ P[j] - np.eye(4))
            assert E[i, j] == pytest.approx(ref, abs=1e-6)


def test_exclude_window_and_revisit():
    # out along x and back: frame k and frame 2n-1-k are at the same place
    n = 50
    fwd = _line_poses(n)
    P = np.concatenate([fwd, fwd[::-1]])
    gt = groundtruth.loop_matrix(P, threshold=0.05, exclude=10)
    assert gt.shape == (100, 100) and (gt == gt.T).all() and not gt.diagonal().any()
    i, j = np.nonzero(gt)
    assert (np.abs(i - j) > 10).all()
    assert gt[0, 99] and gt[10, 89] and not gt[45, 54]  # 45/54 are within the exclusion window
    metric = groundtruth.loop_matrix_metric(P, max_distance=0.05, max_angle=5, exclude=10)
    assert (metric == gt).all()


def test_bad_input():
    P = _line_poses(10)
    with pytest.raises(ValueError, match="threshold must be > 0"):
        groundtruth.loop_matrix(P, 0)
    with pytest.raises(ValueError, match=r"shape \(N, 4, 4\)"):
        groundtruth.loop_matrix(P[:, :3], 0.5)
    with pytest.raises(ValueError, match="max_angle"):
        groundtruth.loop_matrix_metric(P, 1.0, 0)


def test_real_trajectory_start_end_revisit(real_trajectory):
    _, P = sequence.read_trajectory(real_trajectory)
    t0 = time.perf_counter()
    gt = groundtruth.loop_matrix(P, threshold=0.5, exclude=150)
    elapsed = time.perf_counter() - t0
    pairs = groundtruth.loop_pairs(gt)
    assert len(pairs) > 1000
    # the path's end (frames ~2068-2260) revisits its start (frames ~0-138), and nothing else
    assert pairs[:, 0].max() < 200 and pairs[:, 1].min() > 2000
    assert 60 < groundtruth.path_length(P) < 65
    print(f"loop_matrix on 2261 poses: {elapsed:.2f} s, {len(pairs)} pairs")


# ------------------------------------------------------------------ ground truth from loop pairs
def _pair_folder(tmp_path, n, lines, name="seq"):
    """A pose-less sequence folder of n tiny frames with ground_truth.csv holding `lines`."""
    from conftest import write_frames
    folder = write_frames(tmp_path / name, n, size=(8, 6))
    (folder / sequence.GROUND_TRUTH_NAME).write_text("\n".join(lines) + "\n")
    return folder


def test_pairs_tolerance_symmetry_and_exclusion(tmp_path):
    folder = _pair_folder(tmp_path, 40, ["i,j,tolerance", "2,30,1", "5,20", "# a comment", "", "10,12,0"])
    gt = groundtruth.for_sequence(folder, exclude=5)
    assert gt.shape == (40, 40) and gt.dtype == bool
    assert (gt == gt.T).all() and not gt.diagonal().any()
    assert set(map(tuple, groundtruth.loop_pairs(gt))) == {(2, 29), (2, 30), (2, 31), (5, 20)}
    # (10, 12) is within exclude=5 frames: never a loop; with exclude=1 it is
    assert groundtruth.for_sequence(folder, exclude=1)[10, 12]
    # the tolerance widens j only: 1 and 3 are not loops with 30
    assert not gt[1, 30] and not gt[3, 30]
    # the file's pairs are what sequence.read_loop_pairs returns, tolerance 0 where absent
    assert sequence.read_loop_pairs(folder).tolist() == [[2, 30, 1], [5, 20, 0], [10, 12, 0]]
    assert sequence.folder_info(folder)["ground_truth"] == "pairs"
    assert "3 rows, tolerance 0-1 frames" in groundtruth.definition(folder, exclude=5)


def test_pairs_on_a_subset_of_frames(tmp_path):
    folder = _pair_folder(tmp_path, 60, ["i,j,tolerance", "0,40,3", "4,52,0", "8,22,1", "3,50,0"])
    frames = np.arange(0, 60, 4)                       # 0, 4, ..., 56
    gt = groundtruth.for_sequence(folder, frames=frames, exclude=10)
    full = groundtruth.for_sequence(folder, exclude=10)
    assert gt.shape == (15, 15)
    assert (gt == full[np.ix_(frames, frames)]).all()  # the subset is the full matrix's sub-matrix
    got = {(int(frames[a]), int(frames[b])) for a, b in groundtruth.loop_pairs(gt)}
    # 40 +- 3 holds only frame 40 of the subset; 22 +- 1 holds none; i = 3 is not described
    assert got == {(0, 40), (4, 52)}
    # exclude counts original frames, not steps: (8, 20) would be 12 frames = 3 steps apart
    near = _pair_folder(tmp_path, 60, ["i,j", "8,20"], name="near")
    assert groundtruth.for_sequence(near, frames=frames, exclude=11)[2, 5]
    assert not groundtruth.for_sequence(near, frames=frames, exclude=12).any()


def test_poses_come_first_and_match_loop_matrix(tmp_path):
    from conftest import write_frames
    n = 100
    fwd = _line_poses(n // 2)
    P = np.concatenate([fwd, fwd[::-1]])
    folder = write_frames(tmp_path / "posed", n, size=(8, 6))
    sequence.write_trajectory(folder / "CameraTrajectory.txt", np.arange(n), P)
    (folder / sequence.GROUND_TRUTH_NAME).write_text("i,j\n0,50\n")   # ignored: poses come first
    frames = np.arange(0, n, 3)
    gt = groundtruth.for_sequence(folder, frames=frames, threshold=0.05, exclude=10)
    ref = groundtruth.loop_matrix(P[frames], threshold=0.05, exclude=10 // 3)
    assert gt.any() and (gt == ref).all()      # same as the step-wise exclusion for a uniform step
    assert sequence.folder_info(folder)["ground_truth"] == "poses"
    assert groundtruth.definition(folder, 0.05, 10).startswith("Qi 2024 Eq. 5")


@pytest.mark.parametrize("lines, message", [
    (["i,j", "0,40"], r"outside the sequence's frames 0\.\.39"),
    (["i,j", "-1,20"], "outside the sequence"),
    (["i,j,tolerance", "0,20,-2"], "tolerance must be >= 0"),
    (["i,j", "0;20"], r":2: expected `i,j`"),
    (["i,j", "0,20,1,4"], r":2: expected"),
    (["i,j", "0,2.5"], r":2: expected"),
    (["0,20", "1,21"], "first line must be the header"),
    ([], "is empty"),
])
def test_bad_pair_files(tmp_path, lines, message):
    folder = _pair_folder(tmp_path, 40, lines)
    with pytest.raises(ValueError, match=message):
        groundtruth.for_sequence(folder, exclude=5)


def test_bad_arguments_and_no_ground_truth(tmp_path):
    folder = _pair_folder(tmp_path, 40, ["i,j", "0,30"])
    with pytest.raises(ValueError, match="strictly increasing"):
        groundtruth.for_sequence(folder, frames=[0, 8, 4])
    with pytest.raises(ValueError, match="within 0..39"):
        groundtruth.for_sequence(folder, frames=[0, 40])
    with pytest.raises(ValueError, match="integer frame numbers"):
        groundtruth.for_sequence(folder, frames=np.array([0.0, 1.0]))
    with pytest.raises(ValueError, match="exclude"):
        groundtruth.for_sequence(folder, exclude=-1)
    with pytest.raises(ValueError, match="outside"):
        groundtruth.pair_matrix([[0, 40]], 40)
    with pytest.raises(ValueError, match="tolerances"):
        groundtruth.pair_matrix([[0, 30, -1]], 40)
    bare = _pair_folder(tmp_path, 40, ["i,j"], name="bare")
    (bare / sequence.GROUND_TRUTH_NAME).unlink()
    with pytest.raises(groundtruth.NoGroundTruthError, match="add CameraTrajectory.txt .* or ground_truth.csv"):
        groundtruth.for_sequence(bare)
    assert issubclass(groundtruth.NoGroundTruthError, FileNotFoundError)
    assert sequence.folder_info(bare)["ground_truth"] is None


def test_write_loop_pairs_round_trip(tmp_path):
    path = sequence.write_loop_pairs(tmp_path / "gt.csv", [[0, 10], [3, 12]])
    assert path.read_text().splitlines()[0] == "i,j,tolerance"
    assert sequence.read_loop_pairs(path, n_frames=13).tolist() == [[0, 10, 0], [3, 12, 0]]
    with pytest.raises(ValueError, match="outside"):
        sequence.read_loop_pairs(path, n_frames=12)


def test_pair_file_reproduces_the_pose_ground_truth(tiny_sequence, tiny_pairs_sequence):
    info = sequence.folder_info(tiny_pairs_sequence)
    assert info["ground_truth"] == "pairs" and not info["trajectory"] and not info["depth"]
    pairs = sequence.read_loop_pairs(tiny_pairs_sequence)
    assert (pairs[:, 2] > 0).any(), "the fixture should exercise tolerances"
    for frames, exclude in ((None, 20), (np.arange(0, 200, 3), 20), (None, 10)):
        a = groundtruth.for_sequence(tiny_pairs_sequence, frames, exclude=exclude)
        b = groundtruth.for_sequence(tiny_sequence, frames, threshold=0.5, exclude=exclude)
        assert b.any() and (a == b).all()


def test_variants_follow_the_threshold(tiny_sequence, tiny_pairs_sequence):
    v = groundtruth.variants(tiny_sequence, np.arange(0, 200, 2), thresholds=(0.3, 0.5, 0.8), exclude=20)
    eq5 = [v[f"Eq. 5 < {t:g}"] for t in (0.3, 0.5, 0.8)]
    assert list(v)[-1].startswith("metric")
    assert (eq5[1] == groundtruth.for_sequence(tiny_sequence, np.arange(0, 200, 2), 0.5, 20)).all()
    assert not (eq5[0] & ~eq5[1]).any() and not (eq5[1] & ~eq5[2]).any()   # a looser threshold only adds loops
    assert groundtruth.variants(tiny_pairs_sequence) == {}


def test_far_in_time_is_the_one_rule():
    for frames, ex in ((7, 0), (7, 2), (np.array([0, 3, 4, 9, 20]), 4), (np.arange(0, 40, 4), 7)):
        f = np.arange(frames) if np.ndim(frames) == 0 else frames
        want = np.abs(f[:, None] - f[None, :]) > ex
        assert np.array_equal(groundtruth.far_in_time(frames, ex), want)
    with pytest.raises(ValueError, match="exclude must be an integer >= 0"):
        groundtruth.far_in_time(5, -1)
    with pytest.raises(ValueError, match="exclude must be an integer >= 0"):
        groundtruth.far_in_time(5, 1.5)


def test_described_frames_is_the_notebooks_prelude(tiny_sequence):
    n = len(sequence.list_frames(tiny_sequence))
    d = groundtruth.described_frames(tiny_sequence, 3, 0.5, 10)
    assert np.array_equal(d.frames, np.arange(0, n, 3)) and d.exclude_steps == 10 // 3
    assert np.array_equal(d.gt, groundtruth.for_sequence(tiny_sequence, np.arange(0, n, 3), 0.5, 10))
    assert d.summary.startswith(f"{len(d.frames)} frames (frame_step 3), exclusion band 3 steps = 9 original frames")
    assert f"{len(groundtruth.loop_pairs(d.gt))} loop pairs" in d.summary
    with pytest.raises(ValueError, match="frame_step must be an integer >= 1"):
        groundtruth.described_frames(tiny_sequence, 0)
