"""The streams the detector's targets name (experiments.leaderboard.target_protocols): Nordland at
every frame with +- 2 frames, Gardens Point's two named pairs; on tiny textured fakes."""
from pathlib import Path

import cv2
import numpy as np
import pytest

from greenloop.datasets import gardenspoint, nordland
from greenloop.experiments import leaderboard as ex
from greenloop.methods.greenloop_seq import seqmatch, seqstream

N = 40                                     # places per traversal
PARAMS = dict(seq_lens=[3, 5], contrast_windows=[0, 5], velocities=[0.8, 1.0, 1.25], threshold_rule="f1",
              fps_frames=8, timing_repeats=3, weights="auto", input_size=32)


def _place(k: int, t: int, size=(64, 32)) -> np.ndarray:
    """Place k's texture (the same in every traversal), darker and a little noisy in traversal t."""
    base = np.random.default_rng(k).integers(0, 256, (size[1] // 4, size[0] // 4), dtype=np.uint8)
    img = cv2.resize(base, size, interpolation=cv2.INTER_NEAREST).astype(np.float32) * (1.0 - 0.3 * t)
    img += np.random.default_rng(1000 * t + k).normal(0, 4, img.shape)
    return np.repeat(np.clip(img, 0, 255).astype(np.uint8)[..., None], 3, axis=2)


def _fake_gp(root: Path) -> Path:
    for t, name in enumerate(gardenspoint.TRAVERSALS):
        (root / name).mkdir(parents=True)
        for k in range(N):
            cv2.imwrite(str(root / name / f"Image{k:03d}.png"), _place(k, t))
    return root


def _fake_nordland(root: Path) -> Path:
    for t, season in enumerate(nordland.SEASONS):
        (root / season).mkdir(parents=True)
        for k in range(N):
            cv2.imwrite(str(root / season / f"images-{10 * (k + 1):05d}.png"), _place(k, t))
    return root


@pytest.fixture(scope="module")
def gp(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("gp")
    out = gardenspoint.build(tmp / "gardenspoint", _fake_gp(tmp / "src"), size=(64, 32), tolerance=2, progress=False)
    return ex.prepare(str(out), 1, 0.5, 10, 0.5, N, PARAMS)


def _band(n: int, tol: int = 2) -> np.ndarray:
    k = np.arange(n)
    return np.abs(k[:, None] - k[None, :]) <= tol


def test_gardenspoint_pairs_are_the_named_traversals_aligned(gp):
    data, _ = gp
    protos = ex.target_protocols(data, 0.5)
    assert list(protos) == ["day_right -> night_right", "day_left -> night_right"]
    d, s = protos["day_left -> night_right"]
    assert d.frames.tolist() == list(range(N)) + list(range(2 * N, 3 * N))   # day_left, then night_right
    assert (d.GT[:N, N:] == _band(N)).all() and not d.GT[:N, :N].any() and not d.GT[N:, N:].any()
    assert s.reference.tolist() == [True] * N + [False] * N
    assert np.array_equal(d.descriptors["gradients"], data.descriptors["gradients"][d.frames])
    assert d.tune is not None and not (d.tune & d.evalq).any() and d.evalq[N:].any() and not d.evalq[:N].any()


def test_a_pair_run_is_the_default_streamed_over_the_pair_alone(gp):
    data, _ = gp
    d, s = ex.target_protocols(data, 0.5)["day_right -> night_right"]
    run = ex.run_protocol(d, s)
    result, check, carries = run.board, run.stream_check, run.carry
    carry = {c["configuration"]: c for c in carries}
    # its false closures: those threshold_check counts at the fixed threshold, none on this pair
    assert [f["configuration"] for f in run.false_closures] == [] == [c for c in carry if carry[c]["precision_at_fixed_%"] < 100]
    assert list(carry) == [seqmatch.DEFAULT_NAME, seqmatch.CNN_NAME]      # both named configurations run here
    assert carry[seqmatch.CNN_NAME]["threshold_fixed"] == seqmatch.CNN_THRESHOLD and check[seqmatch.CNN_NAME]["equal"]
    carry = carry[seqmatch.DEFAULT_NAME]
    k = seqmatch.DEFAULT_KNOBS
    X = np.concatenate([data.descriptors["gradients"][N:2 * N], data.descriptors["gradients"][2 * N:]])
    S = seqstream.score_matrix(X, d.exclude, k["seq_len"], k["velocities"], 0, None, center_window=k["center_window"],
                               calibrate=k["calibrate"], repeat_cos=k["repeat_cos"], cell_shift=k["cell_shift"])
    rows = result.board.set_index(["method", "mode"])
    pr = rows.loc[(seqmatch.DEFAULT_NAME, "place recognition")]
    assert pr["R@1_%"] == pytest.approx(100 * ex.evaluate.per_query(S, d.GT, d.exclude, d.evalq, s.reference)["R@1"])
    assert pr["R@1_%"] == 100.0                                            # the textures repeat exactly
    m = ex.evaluate.per_query(S, d.GT, d.exclude, d.evalq, s.reference)  # the counts the stream's rows rest on
    assert (pr["queries"], pr["revisit_queries"]) == (m["queries"], m["revisits"]) and m["revisits"] > 0
    assert check[seqmatch.DEFAULT_NAME]["equal"]
    seqslam = rows.loc[("SeqSLAM (published)", "loop closure")]
    assert np.isnan(seqslam["fps_min"]) and np.isnan(seqslam["bytes_per_stored_frame"])   # measured in the leaderboard only
    assert rows.loc[(seqmatch.DEFAULT_NAME, "loop closure"), "bytes_per_stored_frame"] == (
        256 * 4 * len(seqmatch.center_windows(k["center_window"])) + 4 * k["seq_len"])   # one 256-d part per window
    assert set(result.targets.configuration) == {seqmatch.DEFAULT_NAME, seqmatch.CNN_NAME}
    mine = result.targets[result.targets.configuration == seqmatch.DEFAULT_NAME]
    targets = dict(zip(mine.target, mine.met))
    assert targets["R@1 (%), place recognition"] is True
    table, board_rows = ex.protocol_tables(result, {"day_right -> night_right": result})
    assert set(table.protocol) == {"leaderboard", "day_right -> night_right"} and len(board_rows) == len(result.board)
    assert board_rows[["queries", "revisit_queries"]].notna().all().all()   # target_protocols states them too
    lc = rows.loc[(seqmatch.DEFAULT_NAME, "loop closure")]                 # the carry row: the board's closures at
    assert carry["threshold_fixed"] == seqmatch.DEFAULT_THRESHOLD          # the fixed threshold, and the p95 rule's
    assert carry["declared_at_fixed"] == lc["closures_declared"]           # own pick on this tuning part
    assert (carry["queries"], carry["revisit_queries"]) == (lc["queries"], lc["revisit_queries"])
    own = seqmatch.choose_threshold(S, d.GT, d.exclude, d.tune, rule="p95")
    assert carry["threshold_tuning_p95"] == pytest.approx(own, abs=1e-4)
    assert carry["declared_at_tuning_p95"] == seqmatch.closures(S, d.GT, own, d.exclude, d.evalq)["declared"]


def test_nordland_is_every_frame_at_two_frames_whatever_its_own_tolerance(tmp_path):
    out = nordland.build(tmp_path / "nordland", _fake_nordland(tmp_path / "src"), tolerance=0, progress=False)
    data, _ = ex.prepare(str(out), 4, 0.5, 10, 0.5, N, PARAMS)
    (label, (d, s)), = ex.target_protocols(data, 0.5).items()
    assert label == "every frame, +- 2 frames" and d.frame_step == 1 and d.frames.tolist() == list(range(2 * N))
    assert (d.GT[:N, N:] == _band(N)).all()                               # +- 2, not the folder's 0
    assert len(d.descriptors["seqslam"]) == 2 * N and s.reference[:N].all() and not s.reference[N:].any()


def test_other_datasets_have_no_protocol_of_their_own(tiny_sequence):
    data, _ = ex.prepare(str(tiny_sequence), 2, 0.5, 10, 0.5, None, PARAMS)
    assert ex.target_protocols(data, 0.5) == {}
