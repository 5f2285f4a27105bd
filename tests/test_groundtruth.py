import time

import numpy as np
import pytest

from greenloop import data, groundtruth


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
    _, P = data.read_trajectory(real_trajectory)
    t0 = time.perf_counter()
    gt = groundtruth.loop_matrix(P, threshold=0.5, exclude=150)
    elapsed = time.perf_counter() - t0
    pairs = groundtruth.loop_pairs(gt)
    assert len(pairs) > 1000
    # the path's end (frames ~2068-2260) revisits its start (frames ~0-138), and nothing else
    assert pairs[:, 0].max() < 200 and pairs[:, 1].min() > 2000
    assert 60 < groundtruth.path_length(P) < 65
    print(f"loop_matrix on 2261 poses: {elapsed:.2f} s, {len(pairs)} pairs")
