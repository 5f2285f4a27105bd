"""The fused descriptor "gradients+efficientnetlite0" (features.layers.extract_fused) and the cell
shift of its gradient part (seqmatch.shift_cells with part=): what the named CNN configuration
(seqmatch.CNN_KNOBS) streams."""
from pathlib import Path

import cv2
import numpy as np
import pytest

from greenloop import features
from greenloop.features import layers
from greenloop.methods.greenloop_seq import seqmatch, seqstream
from greenloop.similarity import l2_normalise

from conftest import run_cli, write_frames
from test_seqspeed import _drive, make_route, recall_at_1  # noqa: E402  (the drives of the target-5 and CLI tests)

ROOT = Path(__file__).resolve().parents[1]
FUSED = seqmatch.CNN_KNOBS["descriptor"]


@pytest.fixture(scope="module")
def frames():
    """Six smooth random colour frames, 64 x 32 RGB (Nordland's size)."""
    rng = np.random.default_rng(3)
    return np.stack([cv2.GaussianBlur(rng.integers(0, 256, (32, 64, 3), dtype=np.uint8), (5, 5), 2) for _ in range(6)])


def test_the_fused_descriptor_is_its_two_parts_each_normalised(frames):
    X, info = features.extract(frames, FUSED, progress=False, return_info=True)
    assert X.shape == (6, features.FUSED_DIM) and info.weights == "imagenet"
    G = features.extract(frames, "gradients", progress=False)
    feats, li = layers.extract_layers(frames, "efficientnetlite0", "imagenet", ("mid",), ("grid2",), progress=False,
                                      width=features.FUSED_WIDTH)
    assert li["input"] == "128x64"                                     # FUSED_WIDTH (128) wide, the 2:1 aspect kept
    np.testing.assert_allclose(X, np.hstack([l2_normalise(G), l2_normalise(feats[("mid", "grid2")])]), atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(X[:, :256], axis=1), 1, rtol=1e-5)
    np.testing.assert_allclose(np.linalg.norm(X[:, 256:], axis=1), 1, rtol=1e-5)
    bgr = features.extract(frames[..., ::-1].copy(), FUSED, progress=False, color="bgr")
    np.testing.assert_allclose(bgr, X, atol=1e-6)                     # the stream's decoded frames give the same


def test_the_int8_backend_keeps_the_gradients_and_the_float_cnn_part_to_a_cosine_of_099(frames, tmp_path):
    """features.FUSED_INT8: the gradients part bit for bit, the CNN part from the full-integer int8
    graph (calibrated on cnn.int8_calibration_frames, which the frames here are not) within a cosine
    of 0.99 of the float graph's on each frame, yet not the float graph's; the calibration set is
    fixed (the same array on every call) and keys the cached descriptors, and a network that runs no TFLite graph refuses int8."""
    from greenloop.datasets.synthetic import build_scene, render_frame, route_world
    scene, (poses, _) = build_scene(1), route_world(200, 1)       # another seed's frames than the calibration's
    rendered = np.stack([cv2.resize(render_frame(scene, poses[i], (160, 120))[0], (64, 32), interpolation=cv2.INTER_AREA)
                         for i in (13, 77, 140)])
    for F in (frames, rendered):
        X, X8 = (features.extract(F, d, progress=False) for d in (FUSED, features.FUSED_INT8))
        assert X8.shape == X.shape and np.array_equal(X8[:, :256], X[:, :256])
        cos = (X[:, 256:] * X8[:, 256:]).sum(1)                       # both parts L2-normalised
        assert np.all(cos >= 0.99) and not np.allclose(X8[:, 256:], X[:, 256:], atol=1e-4), cos
    hits = layers._int8_runner.cache_info().hits
    for f in frames[:2]:                                              # a stream's one frame per call
        features.extract(f[None], features.FUSED_INT8, progress=False)
    assert layers._int8_runner.cache_info().hits == hits + 2         # the graph and its calibration made once
    from greenloop.features import cnn
    calib = cnn.int8_calibration_frames()
    assert calib.shape == (7 * cnn.CALIBRATION_VIEWS, 120, 160, 3) and calib.dtype == np.uint8
    assert cnn.int8_calibration_frames() is calib and calib[:cnn.CALIBRATION_VIEWS].std() > 10
    folder = write_frames(tmp_path / "seq", 3, size=(64, 32))
    m8, m = (features.get(d)._key_meta(folder, 1) for d in (features.FUSED_INT8, FUSED))
    assert m8["int8_calibration"] == cnn.CALIBRATION_KEY and "int8_calibration" not in m   # cached descriptors keyed by it
    with pytest.raises(ValueError, match="no int8 TFLite graph"):
        cnn.predictor(features.get_backbone("vgg19"), None, calibration=calib)   # a Keras application: no graph


def test_the_fused_descriptor_refuses_a_random_network(frames, monkeypatch):
    with pytest.raises(ValueError, match="needs ImageNet weights"):
        features.extract(frames, FUSED, weights=None, progress=False)
    monkeypatch.setattr(features.weights, "imagenet_weights_path", lambda name: None)
    with pytest.raises(features.WeightsNotFoundError, match="efficientnetlite0"):
        features.extract(frames, FUSED, progress=False)               # 'auto' does not fall back to random init


def test_shift_cells_moves_only_the_grid_of_each_part():
    rng = np.random.default_rng(0)
    d, p = int(np.prod(seqmatch.CELL_GRID)), features.FUSED_DIM
    X = rng.normal(size=(3, 2 * p)).astype(np.float32)               # two joined parts (two centring windows)
    for t in (1, -1):
        Y = seqmatch.shift_cells(X, t, p).reshape(3, 2, p)
        parts = X.reshape(3, 2, p)
        for k in range(2):
            np.testing.assert_array_equal(Y[:, k, :d], seqmatch.shift_cells(parts[:, k, :d], t))
            np.testing.assert_array_equal(Y[:, k, d:], parts[:, k, d:])   # the CNN part is not moved
    np.testing.assert_array_equal(seqmatch.shift_cells(X[:, :2 * d], 1, d), seqmatch.shift_cells(X[:, :2 * d], 1))
    with pytest.raises(ValueError, match="begin with"):
        seqmatch.shift_cells(X, 1, 100)                              # narrower than the grid
    with pytest.raises(ValueError, match="begins with the 'gradients' grid"):
        seqstream.score_matrix(rng.normal(size=(40, 300)).astype(np.float32), 10, cell_shift=1)


def test_a_revisit_seen_a_cell_aside_is_found_through_the_fused_layout():
    """A random walk in the fused layout, revisited with its gradient grid moved one cell column and
    a CNN part that shares nothing with the first visit: only the shifted grid can find it, and
    the shift of the fused layout does."""
    rng = np.random.default_rng(1)
    d, p, n0, back = int(np.prod(seqmatch.CELL_GRID)), features.FUSED_DIM, 200, 60
    walk = np.abs(np.cumsum(rng.normal(size=(n0, p)), 0)).astype(np.float32)
    seen = seqmatch.shift_cells(walk[:back], 1, p) + rng.normal(scale=0.05, size=(back, p)).astype(np.float32)
    seen[:, d:] = np.cumsum(rng.normal(size=(back, p - d)), 0)
    X = np.abs(np.concatenate([walk, seen])).astype(np.float32)
    k = {n: v for n, v in seqmatch.CNN_KNOBS.items() if n != "descriptor"}
    r1 = {}
    for shift in (0, 1):
        S = seqstream.score_matrix(X, 50, **dict(k, cell_shift=shift))
        r1[shift] = np.mean([abs(int(S[:j - 50, j].argmax()) - (j - n0)) <= 2 for j in range(n0 + 10, len(X))])
    assert r1[1] >= 0.9 and r1[1] > r1[0], r1


def _detect_cnn(folder, process=True):
    """The closures `python -m greenloop detect FOLDER --method greenloop-seq-cnn` prints (in this
    process unless ``process``)."""
    res = run_cli(["detect", folder, "--method", seqmatch.CNN_NAME], process=process)
    assert res.returncode == 0, res.stderr
    return [line.split("\t") for line in res.stdout.splitlines() if line[:1].isdigit()]


def test_cli_cnn_configuration_is_silent_without_revisit_and_finds_one(tmp_path):
    """`detect --method greenloop-seq-cnn` with no knobs (CNN_KNOBS at CNN_THRESHOLD): silent on
    tests/test_seqspeed.py's 500-frame pan that never comes back; on the same drive whose last 150
    frames revisit places 0..149 it declares closures, each at its place."""
    assert _detect_cnn(_drive(tmp_path / "once", range(500)), process=False) == []
    rows = _detect_cnn(_drive(tmp_path / "back", list(range(350)) + list(range(150))))
    assert len(rows) >= 75
    assert all(int(r[0]) >= 350 and abs(int(r[1]) - (int(r[0]) - 350)) <= 2 for r in rows)


@pytest.fixture(scope="module")
def fused_route():
    """tests/test_seqspeed.py's route and 1x revisit in the fused layout's width."""
    return make_route(features.FUSED_DIM)


@pytest.mark.parametrize("kind", ["0.5", "0.75", "1.5", "2", "stop", "reverse"])
def test_the_cnn_configuration_keeps_speed_changes_and_reverse_revisits(fused_route, kind):
    """#28's target 5 for greenloop-seq-cnn (its knobs, the fused layout's width): a replay at 0.5x to
    2x, a 30-frame stop or the revisit driven the other way costs at most 5 points of R@1."""
    knobs = {k: v for k, v in seqmatch.CNN_KNOBS.items() if k != "descriptor"}
    base = recall_at_1(fused_route, "1", **knobs)
    assert base >= 0.85
    assert recall_at_1(fused_route, kind, **knobs) >= base - 0.05
