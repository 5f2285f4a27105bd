"""greenloop.mapping: a square route's drifting odometry corrected by one true loop; a planted false
loop wrecks plain LM and is rejected by GNC; Umeyama, ATE, RPE and the end-point error against
known answers; the drift model's determinism and growth; ``python -m greenloop slam`` end to end."""
import numpy as np
import pytest

from greenloop import detect
from greenloop.cli import main as cli_main
from greenloop.datasets import odometry, sequence
from greenloop.mapping import metrics, posegraph, slam
from greenloop.mapping import trajectory as tj
from greenloop.methods.interface import Closure

SIDE, STEP = 10.0, 0.1


@pytest.fixture(scope="module")
def square():
    """(ground truth, odometry, the true loop, a false loop) on a 10 m square walked once; the heading
    bias doubled (0.01 rad/m) so that 40 m of route drift well beyond the loop's sigmas."""
    gt = tj.rectangle_route(SIDE, SIDE, STEP)
    n = len(gt)
    odo = tj.drift_poses(gt, seed=1, heading_bias=0.01)
    true = posegraph.loops_from_poses(gt, [(n - 3, 2)])
    false = posegraph.Loop(n // 2, 20, true[0].T.copy())      # opposite corners, a true loop's pose
    return gt, odo, true, false


def test_rectangle_route_closes_and_walks_its_perimeter():
    gt = tj.rectangle_route(4, 6, 0.5, laps=2)
    assert np.allclose(gt[0], np.eye(4)) and np.allclose(gt[-1, :3, 3], 0, atol=1e-9)
    assert tj.distances(gt)[-1] == pytest.approx(2 * 2 * (4 + 6))
    assert tj.plane_axes(gt) == (0, 2)                  # x-z: camera axes, y down
    with pytest.raises(ValueError, match="step_m"):
        tj.rectangle_route(4, 6, 0)


def test_one_true_loop_removes_most_of_the_drift(square):
    gt, odo, true, _ = square
    before = metrics.ate(gt, odo)
    assert before > 0.3
    for method in ("lm", "gnc"):
        r = posegraph.optimize(odo, true, method)
        assert metrics.ate(gt, r.poses) < 0.15 * before
        assert metrics.end_point_error(gt, r.poses) < 0.1 * metrics.end_point_error(gt, odo)
        assert r.weights == pytest.approx([1.0], abs=1e-3)
    alone = posegraph.optimize(odo, [], "gnc")                 # no loop: the odometry stays as it was
    assert np.allclose(alone.poses, odo, atol=1e-6) and alone.weights.shape == (0,)


def test_a_false_loop_wrecks_plain_lm_and_gnc_rejects_it(square):
    gt, odo, true, false = square
    true_only = metrics.ate(gt, posegraph.optimize(odo, true, "gnc").poses)
    lm = posegraph.optimize(odo, true + [false], "lm")
    assert metrics.ate(gt, lm.poses) > metrics.ate(gt, odo)    # worse than no loop at all
    assert np.all(lm.weights == 1.0)
    gnc = posegraph.optimize(odo, true + [false], "gnc")
    assert gnc.weights[1] < 1e-3 and gnc.weights[0] > 0.99
    assert metrics.ate(gt, gnc.poses) == pytest.approx(true_only, rel=1e-3)
    cauchy = posegraph.optimize(odo, true + [false], "cauchy")  # a kernel down-weights, keeps some pull
    assert cauchy.weights[1] < 0.01 < 0.9 < cauchy.weights[0]


def test_pose2_for_a_planar_robot_corrects_and_rejects_alike(square):
    gt, odo, true, false = square
    flat = tj.make_poses([[0, 0.3, 0], [0, -2.0, 0]], [[1, 0, 2], [-3, 0, 0.5]])   # turns about y only
    assert np.allclose(tj.from_planar(tj.to_planar(flat, (0, 2)), (0, 2)), flat)
    gnc = posegraph.optimize(odo, true + [false], "gnc", planar=True)
    assert gnc.weights[1] < 1e-3 and gnc.weights[0] > 0.99
    assert metrics.ate(gt, gnc.poses) < 0.15 * metrics.ate(gt, odo)
    lifted = gnc.poses[:, 1, 3] - odo[:, 1, 3]                               # height stays the odometry's
    assert np.allclose(lifted, 0, atol=1e-9)
    assert metrics.ate(gt, posegraph.optimize(odo, true + [false], "lm", planar=True).poses) > metrics.ate(gt, odo)


def test_a_direction_only_loop_fixes_rotation_and_weakly_translation(square):
    gt, odo, true, _ = square
    n = len(gt)
    (loop,) = posegraph.loops_from_poses(gt, [(n - 3, 2)], metric=False)
    assert np.linalg.norm(loop.T[:3, 3]) == pytest.approx(1.0)
    noise = posegraph.Noise()
    T, (sigma_r, sigma_t) = posegraph.loop_measurement(loop, odo, noise)
    d = np.linalg.norm(odo[2, :3, 3] - odo[n - 3, :3, 3])         # the odometry's distance gives the scale
    assert np.linalg.norm(T[:3, 3]) == pytest.approx(d)
    assert np.allclose(T[:3, 3] / d, loop.T[:3, 3]) and np.allclose(T[:3, :3], loop.T[:3, :3])
    assert sigma_t == pytest.approx(max(noise.loop_trans_m, d)) and sigma_t > 5 * noise.loop_trans_m
    assert sigma_r == pytest.approx(np.radians(noise.loop_rot_deg))
    metric_ate = metrics.ate(gt, posegraph.optimize(odo, true, "gnc").poses)
    direction = posegraph.optimize(odo, [loop], "gnc")
    assert direction.weights[0] > 0.99
    assert metric_ate < metrics.ate(gt, direction.poses) < 0.5 * metrics.ate(gt, odo)


def test_bad_loops_and_back_ends_raise():
    odo = tj.rectangle_route(2, 2, 0.5)
    with pytest.raises(ValueError, match="joins frames 3 and 99"):
        posegraph.optimize(odo, [posegraph.Loop(3, 99, np.eye(4))], "lm")
    with pytest.raises(ValueError, match="unknown back end 'pcm'"):
        posegraph.optimize(odo, [], "pcm")
    with pytest.raises(ValueError, match=r"\(N, 4, 4\)"):
        posegraph.optimize(odo[:, :3], [], "lm")


def test_inject_false_loops_adds_the_fraction_far_apart(square):
    gt, _, true, _ = square
    many = posegraph.loops_from_poses(gt, [(len(gt) - 1 - k, k) for k in range(6)])
    loops, is_false = posegraph.inject_false_loops(many, len(gt), 0.25, seed=3, positions=gt[:, :3, 3])
    assert len(loops) == 8 and is_false.tolist() == [False] * 6 + [True] * 2
    for lp in loops[6:]:
        assert abs(lp.i - lp.j) >= len(gt) // 10
        assert np.linalg.norm(gt[lp.i, :3, 3] - gt[lp.j, :3, 3]) >= 5.0
        assert any(np.allclose(lp.T, t.T) for t in many)        # looks like a loop
    again, _ = posegraph.inject_false_loops(many, len(gt), 0.25, seed=3, positions=gt[:, :3, 3])
    assert [(lp.i, lp.j) for lp in again] == [(lp.i, lp.j) for lp in loops]
    assert len(posegraph.inject_false_loops(many, len(gt), 0.5, seed=0)[0]) == 12
    assert len(posegraph.inject_false_loops(many, len(gt), 0.0, seed=0)[0]) == 6
    with pytest.raises(ValueError, match="fraction"):
        posegraph.inject_false_loops(many, len(gt), 1.0, seed=0)


def test_gnc_holds_the_true_loops_result_over_the_robustness_curve():
    """Two laps, 8 true loops between them, false loops injected at 10-50 % of the loop factors:
    GNC keeps every true loop, drops every false one, and ends where the true loops alone end; plain
    LM ends worse than the odometry at every fraction."""
    gt = tj.rectangle_route(10, 10, 0.1, laps=2)
    n, lap = len(gt), len(gt) // 2
    odo = tj.drift_poses(gt, seed=2)
    true = posegraph.loops_from_poses(gt, [(lap + k, k) for k in range(20, lap - 20, 50)])
    assert len(true) == 8
    alone = metrics.ate(gt, posegraph.optimize(odo, true, "gnc").poses)
    assert alone < 0.1 * metrics.ate(gt, odo)
    for fraction in (0.1, 0.3, 0.5):
        loops, is_false = posegraph.inject_false_loops(true, n, fraction, seed=0, positions=gt[:, :3, 3])
        gnc = posegraph.optimize(odo, loops, "gnc")
        assert np.all(gnc.weights[is_false] < 0.01) and np.all(gnc.weights[~is_false] > 0.99)
        assert metrics.ate(gt, gnc.poses) == pytest.approx(alone, rel=1e-3)
        assert metrics.ate(gt, posegraph.optimize(odo, loops, "lm").poses) > metrics.ate(gt, odo)


def _random_poses(n, seed):
    rng = np.random.default_rng(seed)
    return tj.make_poses(rng.normal(0, 0.5, (n, 3)), rng.normal(0, 3, (n, 3)))


def test_umeyama_recovers_a_known_rigid_transform():
    rng = np.random.default_rng(0)
    x = rng.normal(0, 2, (50, 3))
    g = tj.make_poses([[0.3, -1.2, 0.7]], [[4.0, -2.0, 1.5]])[0]
    y = x @ g[:3, :3].T + g[:3, 3]
    r, t, c = metrics.umeyama(x, y)
    assert np.allclose(r, g[:3, :3], atol=1e-10) and np.allclose(t, g[:3, 3], atol=1e-10) and c == 1.0
    r, t, c = metrics.umeyama(x, 2.5 * y, with_scale=True)
    assert c == pytest.approx(2.5) and np.allclose(r, g[:3, :3], atol=1e-10)
    est = _random_poses(30, 1)
    ref = g @ est
    assert metrics.ate(ref, est) == pytest.approx(0.0, abs=1e-9)
    assert metrics.ate(ref, est, aligned=False) > 1.0
    assert np.allclose(metrics.align(ref, est), ref, atol=1e-9)
    with pytest.raises(ValueError, match="degenerate"):
        metrics.umeyama(np.zeros((5, 3)), np.zeros((5, 3)))


def test_ate_of_a_known_offset_and_the_end_point_error():
    ref = tj.rectangle_route(3, 5, 0.25)
    est = ref.copy()
    est[:, 1, 3] += np.where(np.arange(len(ref)) % 2 == 0, 0.1, -0.1)   # +-0.1 m: alignment cannot remove it
    assert metrics.ate(ref, est) == pytest.approx(0.1, abs=1e-3)
    moved = tj.make_poses([[0, 0.4, 0]], [[1, 2, 3]])[0] @ ref            # a rigid motion: no drift at the end
    assert metrics.end_point_error(ref, moved) == pytest.approx(0.0, abs=1e-9)
    drift = ref.copy()
    drift[-1, :3, 3] += [0.3, 0.0, 0.4]
    assert metrics.end_point_error(ref, drift) == pytest.approx(0.5)
    with pytest.raises(ValueError, match="associate"):
        metrics.ate(ref, est[:-1])


def test_rpe_is_zero_for_identical_and_the_offset_per_step():
    ref = _random_poses(40, 2)
    zero = metrics.rpe(ref, ref)
    assert zero.translation_m == pytest.approx(0, abs=1e-9) and zero.rotation_deg == pytest.approx(0, abs=1e-5)
    assert zero.pairs == 39
    offset = tj.make_poses([[0, 0, np.radians(2.0)]], [[0.03, 0.0, 0.04]])[0]   # 5 cm and 2 degrees a step
    est = tj.integrate(ref[0], tj.steps(ref) @ offset)
    r = metrics.rpe(ref, est, delta=1)
    assert r.translation_m == pytest.approx(0.05) and r.rotation_deg == pytest.approx(2.0)
    assert metrics.rpe(ref, est, delta=5).pairs == 7                             # (0, 5), ..., (30, 35)
    assert metrics.rpe(ref, est, delta=5, all_pairs=True).pairs == 35


def test_rpe_pairs_in_metres_follow_the_travelled_distance():
    line = tj.integrate(np.eye(4), [tj.make_poses([[0, 0, 0]], [[0, 0, 0.125]])[0]] * 100)  # exact in binary
    pairs = metrics.rpe_pairs(line, 1.0, "m")
    assert np.all(np.diff(pairs, axis=1) == 8) and pairs[0, 0] == 8 and len(pairs) == 11
    allp = metrics.rpe_pairs(line, 1.0, "m", all_pairs=True)
    assert len(allp) == 93 and np.all(allp[:, 1] - allp[:, 0] == 8)
    slow = line.copy()
    slow[:, :3, 3] *= 0.5                                   # the estimate travels half as far
    assert metrics.rpe(line, slow, 1.0, "m").pairs == 5                              # evo: pairs along the estimate
    assert metrics.rpe(line, slow, 1.0, "m", pairs_from_reference=True).pairs == 11
    with pytest.raises(ValueError, match="no pair"):
        metrics.rpe_pairs(line, 50.0, "m")
    with pytest.raises(ValueError, match="unit"):
        metrics.rpe_pairs(line, 1.0, "seconds")


def test_associate_matches_nearest_stamps_within_max_diff():
    a = np.array([0.0, 1.0, 2.0, 3.0])
    b = np.array([0.005, 1.5, 2.001, 2.999, 10.0])
    ia, ib = metrics.associate(a, b, max_diff=0.01)
    assert ia.tolist() == [0, 2, 3] and ib.tolist() == [0, 2, 3]
    with pytest.raises(ValueError, match="time bases"):
        metrics.associate(a, b + 100)


def test_drift_poses_is_the_datasets_model_lifted_to_se3():
    """mapping's odometry is datasets.odometry's drift model on the floor plane: seeded, the truth with
    no drift, the planar model's poses on the floor, the truth's height, pitch and roll kept."""
    gt = tj.rectangle_route(20, 20, 0.1)
    gt = gt @ tj.make_poses([[0.2, 0, 0]], [[0, 0, 0]])[0]                        # a pitched camera
    gt[:, 1, 3] = -0.8                                                            # at a height (y down)
    a = tj.drift_poses(gt, seed=4)
    assert np.array_equal(a, tj.drift_poses(gt, seed=4)) and not np.allclose(a, tj.drift_poses(gt, seed=5))
    assert np.allclose(a[0], gt[0])
    assert np.allclose(tj.drift_poses(gt, 4, scale_error=0, slip=0, heading_bias=0, heading_noise=0), gt)
    planar = odometry.simulate_odometry(tj.to_planar(gt, tj.FLOOR), seed=4)
    floor = tj.to_planar(a, tj.FLOOR)                                             # the one model, on the floor
    assert np.allclose(floor[:, :2], planar[:, :2]) and np.allclose(np.exp(1j * floor[:, 2]), np.exp(1j * planar[:, 2]))
    assert np.allclose(a[:, 1, 3], -0.8)                                          # height kept
    assert np.allclose(tj.rotation_angle(tj.relative(gt, a)), np.abs(np.angle(np.exp(1j * (planar[:, 2] -
                       tj.to_planar(gt, tj.FLOOR)[:, 2])))), atol=1e-9)           # only the yaw drifts
    assert metrics.ate(gt, a) > 0.3


def test_write_tum_reads_back_through_read_odometry(tmp_path):
    poses = _random_poses(12, 7)
    out = tj.write_tum(tmp_path / "t.tum", np.arange(12), poses)
    stamps, back = odometry.read_odometry(out)
    assert np.array_equal(stamps, np.arange(12)) and np.allclose(back, poses, atol=1e-8)
    with pytest.raises(ValueError, match="one stamp per pose"):
        tj.write_tum(tmp_path / "u.tum", np.arange(3), poses)


def test_read_closures_takes_detects_columns_and_skips_rows_without_a_pose(tmp_path):
    f = tmp_path / "matches.csv"
    f.write_text("frame,file,match,match_file,score,closure,rx,ry,rz,tx,ty,tz,metric\n"
                 "5,5.png,1,1.png,3.2,1,0,0.1,0,0.5,0,0,1\n"
                 "6,6.png,2,2.png,1.0,0,,,,,,,\n"
                 "7,7.png,,,,1,,,,,,,\n"
                 "8,8.png,3,3.png,2.9,1,0,0,0,0,0,1,0\n")
    loops, skipped = slam.read_closures(f)
    assert skipped == 2 and [(lp.i, lp.j, lp.metric) for lp in loops] == [(5, 1, True), (8, 3, False)]
    # detect's columns are T_match_query; the loop factor holds T_query_match, its inverse
    assert np.allclose(loops[0].T, tj.inverse(tj.make_poses([[0, 0.1, 0]], [[0.5, 0, 0]]))[0])
    (tmp_path / "bad.csv").write_text("query,match,rx\n1,2,0\n")
    with pytest.raises(ValueError, match="lacks ry"):
        slam.read_closures(tmp_path / "bad.csv")


def test_slam_command_writes_a_trajectory_that_reads_back(tmp_path, square, capsys):
    gt, odo, true, false = square
    folder = tmp_path / "rec"
    folder.mkdir()
    sequence.write_trajectory(folder / "CameraTrajectory.txt", np.arange(len(gt)), gt)
    tj.write_tum(tmp_path / "odo.tum", np.arange(len(odo)), odo)
    rows = ["query,match,rx,ry,rz,tx,ty,tz,metric"]
    for lp in (true[0], false):                       # written as detect writes them: T_match_query
        back = tj.inverse(lp.T[None])[0]
        rv, t = tj.rotvecs(back[None])[0], back[:3, 3]
        rows.append(f"{lp.i},{lp.j}," + ",".join(f"{v:.12g}" for v in (*rv, *t)) + ",1")
    (tmp_path / "closures.csv").write_text("\n".join(rows) + "\n")
    out = tmp_path / "out" / "traj.tum"
    assert cli_main(["slam", str(folder), "--odometry", str(tmp_path / "odo.tum"), "--closures",
                     str(tmp_path / "closures.csv"), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "1 of 2 loop factors kept" in printed and "ATE" in printed
    stamps, poses = odometry.read_odometry(out)
    assert len(poses) == len(gt) and np.array_equal(stamps, np.arange(len(gt)))
    assert metrics.ate(gt, poses) < 0.15 * metrics.ate(gt, odo)
    weights = (out.parent / "traj_loops.csv").read_text().splitlines()
    assert weights[0] == "query,match,metric,weight,kept" and weights[1].endswith(",1") and weights[2].endswith(",0")
    assert cli_main(["slam", str(tmp_path / "none"), "--odometry", str(tmp_path / "odo.tum"),
                     "--out", str(out)]) == 2


def test_plot_draws_every_trajectory_and_loop(square):
    gt, odo, true, false = square
    r = posegraph.optimize(odo, true + [false], "gnc")
    fig = metrics.plot_trajectories(gt, odo, r.poses, true + [false], r.weights)
    ax = fig.axes[0]
    assert len(ax.lines) == 5 and ax.get_xlabel() == "x (m)" and ax.get_ylabel() == "z (m)"
    assert ax.lines[4].get_color()[0] > 0.6 > ax.lines[4].get_color()[1]      # the rejected loop: red
    import matplotlib.pyplot as plt
    plt.close(fig)


def test_slam_on_a_bag_takes_the_odometry_topic_at_each_frames_time(tmp_path, capsys):
    """A ROS 1 bag with a camera topic and two Odometry topics: each frame gets the odometry pose at its
    time (interpolated), the corrected trajectory is stamped with the frames' times."""
    from tests.test_recording import CAM, ODOM, _frames, write_bag
    ostamps = 10.0 + 0.5 * np.arange(9)
    opos = tj.integrate(np.eye(4), [tj.make_poses([[0, 0, 0]], [[0, 0, 1.0]])[0]] * 8)   # 1 m per 0.5 s
    fstamps = 10.05 + 0.5 * np.arange(7)                                         # 0.05 s after each
    bag = write_bag(tmp_path / "rec.bag", True, _frames(7), fstamps, (), (opos, ostamps))
    stamps, poses = slam.frame_odometry(bag, bag, topic=ODOM, camera_topic=CAM)
    assert np.allclose(stamps, fstamps) and np.allclose(poses[:, 2, 3], 0.1 + np.arange(7))
    out = tmp_path / "traj.tum"
    assert cli_main(["slam", str(bag), "--odometry", str(bag), "--odometry-topic", ODOM, "--topic", CAM,
                     "--out", str(out)]) == 0
    back_stamps, back = odometry.read_odometry(out)
    assert np.allclose(back_stamps, fstamps, atol=1e-6) and np.allclose(back[:, 2, 3], 0.1 + np.arange(7), atol=1e-6)
    with pytest.raises(ValueError, match="no odometry pose within"):
        slam.frame_odometry(bag, bag, topic=ODOM, camera_topic=CAM, max_dt=0.01)
    kitti = tmp_path / "odo.txt"
    kitti.write_text("\n".join(" ".join(f"{v:.12g}" for v in p[:3].ravel()) for p in opos) + "\n")
    with pytest.raises(ValueError, match="KITTI file .no times"):
        slam.frame_odometry(bag, kitti, camera_topic=CAM)


def test_a_folders_frames_take_the_pose_stamped_with_their_number(tmp_path, tiny_sequence):
    """A sequence folder's frame k takes the KITTI file's line k (no times: the folder's convention);
    too short a file leaves frames without a pose, a ValueError counting them."""
    n = len(sequence.list_frames(tiny_sequence))
    poses = _random_poses(n, 3)
    kitti = tmp_path / "odo.txt"
    kitti.write_text("\n".join(" ".join(f"{v:.12g}" for v in p[:3].ravel()) for p in poses[::-1]) + "\n")
    stamps, got = slam.frame_odometry(tiny_sequence, kitti)
    assert np.array_equal(stamps, np.arange(n)) and np.allclose(got, poses[::-1], atol=1e-9)
    short = tmp_path / "short.txt"
    short.write_text("\n".join(kitti.read_text().splitlines()[: n // 2]) + "\n")
    with pytest.raises(ValueError, match=f"{n - n // 2} of {n} frames"):
        slam.frame_odometry(tiny_sequence, short)


def test_a_verified_closures_pose_becomes_the_loop_factor_of_the_true_poses():
    """verification and detect's --matches give T_match_query = inv(T_w_match) T_w_query; the loop factor
    of the same pair built from true poses holds T_query_match: loop_from_closure turns one into the other."""
    poses = _random_poses(6, 3)
    T_mq = tj.inverse(poses[4][None])[0] @ poses[1]
    loop = posegraph.loop_from_closure(1, 4, T_mq[:3, :3], T_mq[:3, 3], True)
    truth = posegraph.loops_from_poses(poses, [(1, 4)])[0]
    assert (loop.i, loop.j, loop.metric) == (1, 4, True) and np.allclose(loop.T, truth.T)
    assert not np.allclose(loop.T, T_mq)                      # the convention matters for a non-trivial pair


def test_slam_without_a_closures_file_uses_detects_closures(tmp_path, square, capsys, monkeypatch):
    """With no --closures, slam takes the closures detect declares on the recording (detect.closures_of):
    a verified closure (its T_match_query from the true poses) becomes a loop factor that corrects the
    drift; an unverified one (no pose) is left out and counted."""
    gt, odo, true, _ = square
    folder = tmp_path / "rec"
    folder.mkdir()
    sequence.write_trajectory(folder / "CameraTrajectory.txt", np.arange(len(gt)), gt)
    tj.write_tum(tmp_path / "odo.tum", np.arange(len(odo)), odo)
    q, m = true[0].i, true[0].j
    T_mq = tj.inverse(gt[m][None])[0] @ gt[q]
    planted = [Closure(q, m, 5.0, True, 120, "pnp", T_mq[:3, :3], T_mq[:3, 3], True),
               Closure(q - 1, m - 1, 4.0, None, 0, "too-small", None, None, False)]
    asked = []
    monkeypatch.setattr(detect, "closures_of", lambda rec, topic=None: asked.append((rec, topic)) or planted)
    out = tmp_path / "traj.tum"
    assert cli_main(["slam", str(folder), "--odometry", str(tmp_path / "odo.tum"), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert asked == [(str(folder), None)] and "# detect: 2 closures, 1 with a verified pose" in printed
    assert "1 of 1 loop factors kept (1 of detect's closures without a verified pose left out)" in printed
    assert metrics.ate(gt, odometry.read_odometry(out)[1]) < 0.15 * metrics.ate(gt, odo)
