"""The Siamese CNN of Xu et al. 2022: losses by hand, shared weights, fusions, pairs kept out of
the held-out part, the training cache."""
import json
import math

import numpy as np
import pytest

from greenloop import evaluate
from greenloop.methods.siamese import siamese as sm

W = 0.25            # small networks: the tests check structure and numbers, not accuracy
S = 32              # input size (any size works: "same" padding)


def _frames(n, c, seed=0):
    return np.random.default_rng(seed).random((n, S, S, c)).astype(np.float32)


def _loop_gt(n=120, shift=90, length=30):
    """Frames shift .. shift+length-1 revisit frames 0 .. length-1 (i <-> i + shift)."""
    gt = np.zeros((n, n), bool)
    i = np.arange(length)
    gt[i, i + shift] = gt[i + shift, i] = True
    return gt


# ------------------------------------------------------------------------------------ losses
def test_contrastive_loss_by_hand():
    d = np.array([0.5, 0.2, 1.5, 0.0, 0.9], np.float32)
    same = np.array([1, 0, 0, 1, 0])
    # same: 0.5 d^2; different: 0.5 max(0, m - d)^2, m = 1
    expected = [0.5 * 0.25, 0.5 * 0.8 ** 2, 0.0, 0.0, 0.5 * 0.1 ** 2]
    got = np.asarray(sm.contrastive_loss(d, same, margin=1.0))
    assert got == pytest.approx(expected, abs=1e-6)
    # a larger margin pushes the far negative too: 0.5 (2 - 1.5)^2
    assert float(np.asarray(sm.contrastive_loss(d, same, margin=2.0))[2]) == pytest.approx(0.125)
    assert float(np.asarray(sm.contrastive_loss(d, same.astype(bool), 1.0))[1]) == pytest.approx(0.32)


def test_softmax_and_multitask_loss_by_hand():
    ln3 = math.log(3.0)
    logits_a = np.array([[0.0, ln3], [0.0, 0.0]], np.float32)     # p = (1/4, 3/4), (1/2, 1/2)
    logits_b = np.array([[ln3, 0.0], [0.0, 0.0]], np.float32)     # p = (3/4, 1/4), (1/2, 1/2)
    labels_a, labels_b = np.array([1, 0]), np.array([0, 1])
    ce_a = -np.log([0.75, 0.5])
    ce_b = -np.log([0.75, 0.5])
    assert np.asarray(sm.softmax_loss(labels_a, logits_a)) == pytest.approx(ce_a, abs=1e-6)
    assert float(np.asarray(sm.softmax_loss(np.array([0]), logits_a[:1]))[0]) == pytest.approx(math.log(4))
    d, same = np.array([0.5, 0.2], np.float32), np.array([1, 0])
    cst = np.array([0.125, 0.32])                                 # 0.5 * 0.5^2, 0.5 * 0.8^2
    for lam in (0.0, 0.5, 2.0):
        got = np.asarray(sm.multitask_loss(d, same, logits_a, logits_b, labels_a, labels_b, 1.0, lam))
        assert got == pytest.approx(ce_a + ce_b + lam * cst, abs=1e-6)
    # pair 0 with lambda 0.5: 2 * -ln(3/4) + 0.0625
    assert float(np.asarray(sm.multitask_loss(d, same, logits_a, logits_b, labels_a, labels_b, 1.0, 0.5))[0]) \
        == pytest.approx(2 * 0.2876821 + 0.0625, abs=1e-6)


def test_compiled_siamese_optimises_the_multitask_loss():
    siamese, desc = sm.build(4, (S, S, 3), "multitask", width=W, lam=0.5, margin=1.0)
    xa, xb = _frames(6, 3, 1), _frames(6, 3, 2)
    xb[:2] = xa[:2]                                               # two pairs of identical images
    same = np.array([1, 1, 0, 0, 1, 0], np.float32)
    la, lb = np.array([0, 1, 2, 3, 0, 1]), np.array([0, 1, 3, 2, 0, 2])
    out = siamese.predict_on_batch([xa, xb])
    assert set(out) == {"distance", "logits_a", "logits_b"}
    expected = np.mean(np.asarray(sm.multitask_loss(out["distance"], same, out["logits_a"],
                                                    out["logits_b"], la, lb, 1.0, 0.5)))
    logs = siamese.test_on_batch([xa, xb], {"distance": same, "logits_a": la, "logits_b": lb},
                                 return_dict=True)
    assert logs["loss"] == pytest.approx(float(expected), rel=1e-5)


# ------------------------------------------------------------------------------- structure
def test_branches_share_one_set_of_weights():
    siamese, desc = sm.build(None, (S, S, 3), "contrastive", width=W)
    assert len(siamese.trainable_weights) == len(desc.trainable_weights)     # not twice as many
    assert {id(v) for v in siamese.trainable_weights} == {id(v) for v in desc.trainable_weights}
    x, y = _frames(4, 3, 0), _frames(4, 3, 1)
    d_same = np.asarray(siamese.predict_on_batch([x, x])["distance"])
    d_diff = np.asarray(siamese.predict_on_batch([x, y])["distance"])
    assert np.all(d_same < 1e-5) and np.all(d_diff > 1e-3)
    F = sm.describe(desc, np.concatenate([x, x]))               # same input -> distance 0
    assert np.linalg.norm(F[:4] - F[4:], axis=1).max() < 1e-5   # (float rounding by batch position)
    multi, desc2 = sm.build(5, (S, S, 3), "multitask", width=W)
    head = multi.get_layer("softmax")
    assert len(multi.trainable_weights) == len(desc2.trainable_weights) + len(head.trainable_weights)


@pytest.mark.parametrize("fusion,channels,layer", [("none", 3, None), ("none", 1, None), ("early", 4, None),
                                                   ("mid", 4, "conv2"), ("late", 4, None)])
def test_each_fusion_gives_n_by_d_descriptors(fusion, channels, layer):
    siamese, desc = sm.build(3, (S, S, channels), "multitask", fusion, layer, width=W)
    X = _frames(5, channels)
    F = sm.describe(desc, X)
    assert F.shape == (5, sm.DESCRIPTOR_DIM) and F.dtype == np.float32
    assert len(desc.inputs) == (2 if fusion in ("mid", "late") else 1)
    F2, info = sm.describe(desc, X, batch_size=2, return_info=True)
    assert np.allclose(F, F2, atol=1e-5)
    assert info.dim == sm.DESCRIPTOR_DIM and info.weights == "trained here" and info.seconds_per_image > 0
    if fusion == "late":                                      # the average of the two streams
        r, d = sm.describe(desc, X, stream="rgb"), sm.describe(desc, X, stream="depth")
        assert np.allclose(F, (r + d) / 2, atol=1e-5)
        assert {k for k in siamese.predict_on_batch(sm._inputs(desc, X) * 2)} == {
            "rgb_distance", "rgb_logits_a", "rgb_logits_b", "depth_distance", "depth_logits_a", "depth_logits_b"}


@pytest.mark.parametrize("layer", sm.LAYERS)
def test_mid_fusion_joins_at_the_named_layer(layer):
    _, desc = sm.build(None, (S, S, 4), "contrastive", "mid", layer, width=W, merge="concat")
    fuse = desc.get_layer(f"fuse_{layer}")
    rgb, dep = desc.get_layer(f"rgb_{layer}"), desc.get_layer(f"depth_{layer}")
    assert tuple(fuse.output.shape[1:3]) == tuple(rgb.output.shape[1:3]) == tuple(dep.output.shape[1:3])
    assert fuse.output.shape[-1] == rgb.output.shape[-1] + dep.output.shape[-1]   # concatenated
    upto = sm.LAYERS[:sm.LAYERS.index(layer) + 1]
    names = {l.name for l in desc.layers}
    assert {f"rgb_{n}" for n in upto} <= names and {f"depth_{n}" for n in upto} <= names
    assert not any(f"rgb_{n}" in names for n in sm.LAYERS[len(upto):])         # one trunk after it
    assert {n for n in sm.LAYERS[len(upto):]} <= names
    assert sm.describe(desc, _frames(3, 4)).shape == (3, sm.DESCRIPTOR_DIM)
    _, summed = sm.build(None, (S, S, 4), "contrastive", "mid", layer, width=W)     # the default: sum
    assert summed.get_layer(f"fuse_{layer}").output.shape[-1] == rgb.output.shape[-1]


def _seeded_mid(layer, merge):
    import keras
    keras.utils.set_random_seed(7)
    return sm.embedding((S, S, 4), "mid", layer, width=W, merge=merge)[0]


@pytest.mark.parametrize("conv,pool", [("conv1", "pool1"), ("conv5", "pool5")])
def test_concat_before_or_after_a_max_pool_is_one_network_a_sum_is_not(conv, pool):
    X = _frames(6, 4, 3)
    a, b = _seeded_mid(conv, "concat"), _seeded_mid(pool, "concat")
    assert [w.shape for w in a.weights] == [w.shape for w in b.weights]
    assert np.allclose(sm.describe(a, X), sm.describe(b, X), atol=1e-5)   # pool(concat) = concat(pool)
    a, b = _seeded_mid(conv, "sum"), _seeded_mid(pool, "sum")
    assert all(np.array_equal(u, v) for u, v in zip(a.get_weights(), b.get_weights()))   # same weights,
    assert not np.allclose(sm.describe(a, X), sm.describe(b, X), atol=1e-3)             # other network


def test_bad_input_raises_value_error():
    bad = [dict(supervision="triplet"), dict(fusion="intermediate", input_shape=(S, S, 4)),
           dict(fusion="mid", fusion_layer="conv6", input_shape=(S, S, 4)),
           dict(fusion="mid", input_shape=(S, S, 4)),
           dict(fusion="early", input_shape=(S, S, 3)), dict(fusion="mid", fusion_layer="conv1"),
           dict(fusion="late", input_shape=(S, S, 1)),
           dict(fusion="early", fusion_layer="conv1", input_shape=(S, S, 4)),
           dict(fusion="mid", fusion_layer="conv1", merge="max", input_shape=(S, S, 4)),
           dict(optimizer="rmsprop"), dict(margin=0.0), dict(n_classes=None, supervision="softmax")]
    for kw in bad:
        kw = dict(dict(n_classes=3, input_shape=(S, S, 3), width=W), **kw)
        with pytest.raises(ValueError):
            sm.build(**kw)
    _, desc = sm.build(3, (S, S, 3), width=W)
    with pytest.raises(ValueError, match="takes frames"):
        sm.describe(desc, _frames(2, 4))
    with pytest.raises(ValueError, match="late-fusion"):
        sm.describe(desc, _frames(2, 3), stream="rgb")
    with pytest.raises(ValueError, match="4 channels"):
        sm.train(_frames(6, 3), np.array([0, 0, 1, 1, -1, -1]), fusion="early", cache=False)


# ---------------------------------------------------------------------------------- pairs
def test_place_labels_merge_revisits_inside_the_training_part():
    gt = _loop_gt()
    train, held = evaluate.split_mask(120, 0.5, gt=gt, gap=5)
    labels = sm.place_labels(train, gt, 20)
    assert (labels[~train] == -1).all() and (labels[train] >= 0).all()
    cut = int(np.flatnonzero(train)[-1]) + 1
    assert cut == 105
    assert (labels[90:cut] == labels[0:cut - 90]).all()        # a revisit is the place it revisits
    assert labels[:90].tolist() == np.repeat(np.arange(5), 20)[:90].tolist()


def test_pairs_never_include_a_heldout_frame_or_its_neighbours():
    gt, gap = _loop_gt(), 5
    train, held = evaluate.split_mask(120, 0.5, gt=gt, gap=gap)
    labels = sm.place_labels(train, gt, 20)
    pairs, same = sm.make_pairs(labels, 4000, seed=0)
    assert pairs.shape == (4000, 2) and same.mean() == 0.5
    dist = np.abs(pairs.ravel()[:, None] - np.flatnonzero(held)[None, :]).min()
    assert dist > gap
    assert train[pairs].all()
    assert (labels[pairs[same, 0]] == labels[pairs[same, 1]]).all()
    assert (labels[pairs[~same, 0]] != labels[pairs[~same, 1]]).all()
    assert (pairs[same, 0] != pairs[same, 1]).all()
    assert ((pairs[same] >= 90).any(1) & (pairs[same] < 90).any(1)).any()   # positives across the revisit
    sm.check_pairs(pairs, held, gap)
    with pytest.raises(ValueError, match="held out"):
        sm.check_pairs(np.array([[0, 1], [2, int(np.flatnonzero(held)[0]) - gap]]), held, gap)
    a, _ = sm.make_pairs(labels, 100, seed=3, positive_fraction=0.25)
    b, s = sm.make_pairs(labels, 100, seed=3, positive_fraction=0.25)
    assert np.array_equal(a, b) and s.sum() == 25
    with pytest.raises(ValueError):
        sm.make_pairs(np.array([0, -1, -1]), 10)



def test_training_split_holds_every_revisit_out_when_no_honest_split_exists():
    gt = _loop_gt()                                               # revisits 90..119: the usual split
    train, held, note = sm.training_split(120, 0.5, gt, 5, 20)
    assert note is None and [a.tolist() for a in evaluate.split_mask(120, 0.5, gt=gt, gap=5)] == [train.tolist(), held.tolist()]
    gt = _loop_gt(shift=116, length=4)                            # revisits 116..119 (span 3), gap 5
    with pytest.raises(evaluate.NoHonestSplit):
        evaluate.split_mask(120, 0.5, gt=gt, gap=5)
    train, held, note = sm.training_split(120, 0.5, gt, 5, 20)    # train 0..110, held 116..119
    assert np.flatnonzero(train).tolist() == list(range(111)) and np.flatnonzero(held).tolist() == [116, 117, 118, 119]
    assert "frames 0..110" in note and "from 116 on" in note
    labels = sm.place_labels(train, gt, 20)
    assert labels.max() == 5 and (labels[~train] == -1).all()      # spots only: 111 frames, 6 places
    pairs, _ = sm.make_pairs(labels, 200, seed=0)
    sm.check_pairs(pairs, held, 5)
    with pytest.raises(evaluate.NoHonestSplit, match="two places"):  # 111 frames hold no two places of 111
        sm.training_split(120, 0.5, gt, 5, 111)

def test_train_uses_only_labelled_frames_and_is_cached(tmp_path):
    gt, gap = _loop_gt(), 5
    train, held = evaluate.split_mask(120, 0.5, gt=gt, gap=gap)
    labels = sm.place_labels(train, gt, 20)
    X = _frames(120, 3)
    kw = dict(supervision="multitask", epochs=2, n_pairs=30, batch_size=10, width=W, cache=tmp_path)
    m1, h1, p1 = sm.train(X, labels, seed=0, **kw)
    assert p1["pairs"].shape == (60, 2) and len(h1["loss"]) == 2 and h1["n_classes"] == labels.max() + 1
    sm.check_pairs(p1["pairs"], held, gap)
    assert train[p1["pairs"]].all()
    folders = [p for p in tmp_path.iterdir() if p.is_dir()]
    assert len(folders) == 1 and (folders[0] / "model.keras").is_file()
    assert json.loads((folders[0] / "params.json").read_text())["supervision"] == "multitask"
    m2, h2, p2 = sm.train(X, labels, seed=0, **kw)                   # loaded, not retrained
    assert h2 == h1 and np.array_equal(p2["pairs"], p1["pairs"])
    assert np.allclose(sm.describe(m1, X[:8]), sm.describe(m2, X[:8]), atol=1e-6)
    assert not list(tmp_path.glob(".tmp-*"))


# ------------------------------------------------------------ scoring (notebook 10)
def test_near_heldout_marks_the_heldout_frames_and_their_neighbours():
    held = np.zeros(10, bool); held[4] = True
    assert np.flatnonzero(sm.near_heldout(held, 2)).tolist() == [2, 3, 4, 5, 6]
    assert np.flatnonzero(sm.near_heldout(held, 0)).tolist() == [4]


# ---------------------------------------------------------- hard negatives, augmentation, learning
def test_negatives_avoid_ground_truth_loops_and_hard_ones_are_the_nearest():
    labels = np.array([0, 0, 1, 1, 2, 2, -1])
    gt = np.zeros((7, 7), bool)
    gt[1, 2] = gt[2, 1] = True                      # frames 1 and 2: two spots, one place by the poses
    pairs, same = sm.make_pairs(labels, 400, seed=0, gt=gt)
    neg = {tuple(sorted(p)) for p in pairs[~same]}
    assert (1, 2) not in neg and (0, 2) in neg and not (pairs == 6).any()
    F = np.array([[0.0], [0.1], [0.2], [5.0], [0.3], [9.0], [0.05]])
    hard = sm.hard_negatives(F, labels, gt, 300, seed=0, k=1)
    # the nearest other-place, non-loop frame of each anchor (frame 6 is unlabelled, 1-2 a loop)
    want = {0: 2, 1: 4, 2: 4, 3: 5, 4: 2, 5: 3}
    assert all(want[a] == b for a, b in hard), hard[:10]
    two = sm.hard_negatives(F, labels, gt, 300, seed=0, k=2)
    assert {(0, 2), (0, 4)} <= {tuple(p) for p in two}               # k = 2: either of the two nearest
    assert all(labels[a] != labels[b] and not gt[a, b] for a, b in two)


def test_augment_moves_and_relights_rgb_and_only_moves_depth():
    rng = np.random.default_rng(0)
    X = _frames(8, 4)
    same = sm.augment(X, rng, shift=0.0, photometric=0.0)
    assert np.array_equal(same, X)
    out = sm.augment(X, np.random.default_rng(1), shift=0.25, photometric=0.0)
    assert out.shape == X.shape and not np.array_equal(out, X)
    for b in range(8):                               # each frame is its own copy moved by a whole number of pixels
        found = any(np.array_equal(out[b, 8:24, 8:24], X[b, 8 - dy:24 - dy, 8 - dx:24 - dx])
                    for dy in range(-8, 9) for dx in range(-8, 9))
        assert found, b
    lit = sm.augment(X, np.random.default_rng(2), shift=0.0, photometric=0.3)
    assert np.array_equal(lit[..., 3], X[..., 3]) and not np.array_equal(lit[..., :3], X[..., :3])
    assert lit.min() >= 0 and lit.max() <= 1


def _revisit_sequence(n_places=8, per_place=10, revisits=6, size=S, seed=0):
    """Places of smooth random colour patterns, then a second pass over the first ``revisits``
    places at half the brightness: raw pixels and an untrained network match the dark second pass
    to each other, a network trained on pairs across the two passes can learn to ignore brightness."""
    import cv2

    rng = np.random.default_rng(seed)
    pats = [cv2.resize(rng.random((4, 4, 3)).astype(np.float32), (size, size), interpolation=cv2.INTER_CUBIC)
            for _ in range(n_places)]
    def frame(p, dark):
        x = np.clip(pats[p] + rng.normal(0, 0.05, pats[p].shape), 0, 1)
        return (0.5 * x if dark else x).astype(np.float32)
    first = [(p, False) for p in range(n_places) for _ in range(per_place)]
    second = [(p, True) for p in range(revisits) for _ in range(per_place)]
    order = first + second
    X = np.stack([frame(p, d) for p, d in order])
    place = np.array([p for p, _ in order])
    gt = (place[:, None] == place[None, :]) & (np.abs(np.arange(len(order))[:, None] - np.arange(len(order))) > per_place * 2)
    return X, gt


def test_a_tiny_siamese_training_learns_what_the_untrained_network_does_not(tmp_path):
    from greenloop.experiments import siamese_rgbd as sr

    X, gt = _revisit_sequence()
    exclude = 20
    train, held, _ = sm.training_split(len(X), 0.5, gt, 5, 10)
    labels = sm.place_labels(train, gt, 10)
    key, monitor = sr.heldout_monitor(X, gt, exclude, held)
    model, hist, _ = sm.train(X, labels, seed=0, supervision="contrastive", epochs=8, n_pairs=200, batch_size=20,
                              width=0.5, gt=gt, hard_fraction=0.5, monitor=(key, monitor), cache=tmp_path)
    rows, _ = sr.reference_scores(X, gt, exclude, held, seeds=[0], width=0.5)
    untrained_ap = rows[0]["AP_%"]
    assert hist["loss"][-1] < 0.7 * hist["loss"][0], hist["loss"]
    assert len(hist["monitor"]) == 8 and hist["monitor"][-1] == pytest.approx(monitor(model))
    assert hist["monitor"][-1] > untrained_ap + 10, (hist["monitor"], untrained_ap)


def test_a_loss_that_keeps_falling_has_not_plateaued_and_a_flat_one_has_at_any_scale():
    """siamese.plateaued: the early-stopping rule on -log(loss), checked after every epoch."""
    falling = 6.0 * 0.95 ** np.arange(30)                        # 5 % lower every epoch
    assert not sm.plateaued(falling)
    flat = np.r_[falling[:10], np.full(20, falling[9])]          # flat from epoch 10: 10 epochs without a fall by 1 %
    assert sm.plateaued(flat) and sm.plateaued(flat / 100)       # scale-free: the contrastive loss is ~0.1
    assert not sm.plateaued(flat[:19])                          # 9 flat epochs: patience 10 not yet spent
    slow = 6.0 * 0.995 ** np.arange(30)                          # 0.5 % per epoch: 10 epochs make about 4.9 %
    assert not sm.plateaued(slow) and sm.plateaued(slow, patience=1)
    assert sm.plateaued(np.r_[falling[:12], falling[11] * 1.3, falling[11] * np.ones(12)])   # a rise is no fall
    assert not sm.plateaued([1.0])                               # one epoch: nothing to compare



def test_early_stopping_stops_on_the_held_out_loss_and_never_trains_on_its_frames(tmp_path):
    gt = _loop_gt()
    train, held = evaluate.split_mask(120, 0.5, gt=gt, gap=5)
    labels = sm.place_labels(train, gt, 20)
    val = sm.validation_frames(labels)
    assert not val[labels < 0].any() and all(val[labels == c].sum() >= 2 for c in np.unique(labels[labels >= 0]))
    X = _frames(120, 3)                 # noise: what a network learns of some frames says nothing of others
    kw = dict(supervision="multitask", epochs=40, n_pairs=40, batch_size=10, width=W, cache=tmp_path)
    _, h, p = sm.train(X, labels, seed=0, stop_patience=2, **kw)
    assert h["stopped"] and len(h["loss"]) == len(h["val_loss"]) < 40 and sm.converged(h)
    assert not val[p["pairs"]].any() and len(p["pairs"]) == 40 * len(h["loss"])     # validation frames: never trained on
    _, fixed, _ = sm.train(X, labels, seed=0, **dict(kw, epochs=3))                  # no patience: the whole budget
    assert len(fixed["loss"]) == 3 and fixed["val_loss"] == [] and not fixed["stopped"]
    with pytest.raises(ValueError, match="stop_patience"):
        sm.train(X, labels, seed=0, stop_patience=-1, **kw)


def test_converged_reads_the_held_out_loss_under_early_stopping_else_the_training_loss():
    falling = list(6.0 * 0.95 ** np.arange(30))
    assert sm.converged({"loss": falling, "val_loss": [1.0, 1.0], "stopped": True})
    assert not sm.converged({"loss": falling[:5], "val_loss": falling[:5], "stopped": False})   # ended on its cap
    assert not sm.converged({"loss": falling, "val_loss": []})                                   # fixed budget: plateaued
    assert sm.converged({"loss": falling[:10] + [falling[9]] * 20})
    short = sm.validation_frames(np.repeat(np.arange(4), 7))                       # 7 frames a place: every 3rd
    assert short.reshape(4, 7).sum(1).tolist() == [2] * 4 and short[:7].tolist() == [0, 1, 0, 0, 1, 0, 0]
    with pytest.raises(ValueError, match="two validation"):
        sm.validation_frames(np.r_[np.zeros(3, int), np.ones(3, int), -np.ones(5, int)])
