import json

import numpy as np
import pytest

from greenloop import cnn, spots
from greenloop.util.cache import cache_key


def _toy(n=120, L=30, seed=0):
    rng = np.random.default_rng(seed)
    y = spots.group(n, L)
    X = (rng.random((n, 32, 32, 1)) * 0.3 + (y[:, None, None, None] + 1) / 6).astype(np.float32)
    return X, y


def test_build_is_the_papers_model():
    m = cnn.build(38)
    kinds = [type(l).__name__ for l in m.layers]
    assert kinds == ["Conv2D", "Flatten", "Dense", "Dense"]
    conv, _, dense, out = m.layers
    assert conv.filters == 32 and conv.kernel_size == (3, 3) and conv.activation.__name__ == "relu"
    assert dense.units == 68 and out.units == 38 and out.activation.__name__ == "softmax"
    assert m.count_params() == 320 + 30 * 30 * 32 * 68 + 68 + 68 * 38 + 38
    assert m.optimizer.learning_rate.numpy() == pytest.approx(1e-3)
    with pytest.raises(ValueError):
        cnn.build(1)


def test_random_split_sizes_match_paper():
    tr, te = cnn.split_indices(spots.group(2260, 60), seed=0)
    assert (len(tr), len(te)) == (1808, 452) and len(np.intersect1d(tr, te)) == 0


def test_blocked_split_keeps_neighbours_out():
    y = spots.group(600, 60)
    tr, te = cnn.split_indices(y, seed=3, split="blocked", gap=5)
    assert len(np.intersect1d(tr, te)) == 0
    dist = np.abs(te[:, None] - tr[None, :]).min(1)
    assert dist.min() > 5  # every test frame is more than `gap` frames from any training frame
    assert set(np.unique(y[te])) == set(np.unique(y))  # every spot is tested
    assert len(te) == 10 * 12
    with pytest.raises(ValueError, match="split must be"):
        cnn.split_indices(y, 0, split="stratified")


def test_centred_blocks_stay_inside_their_spot():
    y = spots.group(600, 60)
    tr, te = cnn.split_indices(y, seed=3, split="blocked", gap=10, block="centre")
    # each spot of 60 frames: the 12 test frames are 24..35, the gap drops 14..23 and 36..45
    assert list(te[:12]) == list(range(24, 36))
    assert list(tr[:14]) == list(range(14)) and tr[14] == 46
    # no frame of another spot is dropped: every spot keeps 60 - 12 - 20 training frames
    assert (np.bincount(y[tr]) == 28).all()
    # the seed does not move a centred block
    assert (cnn.split_indices(y, seed=4, split="blocked", gap=10, block="centre")[1] == te).all()
    with pytest.raises(ValueError, match="block must be"):
        cnn.split_indices(y, 0, split="blocked", block="left")


def test_gap_widens_the_distance_to_training():
    y = spots.group(600, 60)
    for gap in (0, 5, 20):
        tr, te = cnn.split_indices(y, seed=1, split="blocked", gap=gap)
        assert np.abs(te[:, None] - tr[None, :]).min() == gap + 1
    with pytest.raises(ValueError, match="gap must be"):
        cnn.split_indices(y, 0, split="blocked", gap=-1)


def test_train_size_subsamples_the_training_frames():
    y = spots.group(2260, 60)
    tr_full, te_full = cnn.split_indices(y, seed=2)
    tr, te = cnn.split_indices(y, seed=2, train_size=1430)
    assert len(tr) == 1430 and set(tr) <= set(tr_full) and (te == te_full).all()
    assert (tr == cnn.split_indices(y, seed=2, train_size=1430)[0]).all()  # seeded
    with pytest.raises(ValueError, match="train_size must be"):
        cnn.split_indices(y, 0, train_size=1809)


def test_train_is_deterministic_and_learns(tmp_path):
    X, y = _toy()
    a = cnn.train(X, y, seed=1, epochs=3, cache=False, progress=False)
    b = cnn.train(X, y, seed=1, epochs=3, cache=False, progress=False)
    assert a[1]["val_loss"] == b[1]["val_loss"]
    assert (a[2]["test"] == b[2]["test"]).all()
    c = cnn.train(X, y, seed=2, epochs=3, cache=False, progress=False)
    assert a[1]["val_loss"] != c[1]["val_loss"]
    model, hist, split = cnn.train(X, y, seed=1, epochs=15, cache=False, progress=False)
    assert hist["accuracy"][-1] > hist["accuracy"][0]
    assert np.mean(cnn.predict(model, X[split["test"]]) == y[split["test"]]) > 0.5


def test_cache_reuses_and_key_changes(tmp_path):
    X, y = _toy()
    base = dict(seed=0, epochs=2, batch_size=32, test_size=0.2, split="random", n_classes=4, fast="fused",
                gap=None, batch_order="model.fit")
    k0 = cache_key(X, y, **base)
    for name, value in [("seed", 1), ("epochs", 3), ("batch_size", 16), ("test_size", 0.3),
                        ("split", "blocked"), ("n_classes", 5), ("fast", "plain")]:
        assert cache_key(X, y, **dict(base, **{name: value})) != k0, name
    X2 = X.copy(); X2[0, 0, 0, 0] += 0.01
    assert cache_key(X2, y, **base) != k0
    assert cache_key(X, y[::-1].copy(), **base) != k0

    m1, h1, s1 = cnn.train(X, y, seed=0, epochs=2, cache=tmp_path, progress=False)
    folders = [p for p in tmp_path.iterdir() if p.is_dir()]
    assert len(folders) == 1 and (folders[0] / "model.keras").is_file()
    assert json.loads((folders[0] / "params.json").read_text())["epochs"] == 2
    # the key still names the trainer "fast", as before train(trainer=...): older caches stay valid
    assert folders[0].name == k0
    m2, h2, s2 = cnn.train(X, y, seed=0, epochs=2, cache=tmp_path, progress=False)
    assert h2 == h1 and (s2["test"] == s1["test"]).all()
    assert np.allclose(m2.predict(X[:4], verbose=0), m1.predict(X[:4], verbose=0))
    assert not list(tmp_path.glob(".tmp-*"))


def test_run_seeds_reports_accuracy(tmp_path):
    X, y = _toy()
    runs = cnn.run_seeds(X, y, [0, 1], epochs=2, cache=tmp_path, progress=False)
    assert [r["seed"] for r in runs] == [0, 1]
    for r in runs:
        assert r["test_accuracy"] == pytest.approx(np.mean(r["test_pred"] == y[r["split"]["test"]]))


def test_train_rejects_bad_input():
    X, y = _toy()
    with pytest.raises(ValueError, match="X must be"):
        cnn.train(X[:, :, :, 0], y, seed=0, cache=False)
    with pytest.raises(ValueError, match="epochs"):
        cnn.train(X, y, seed=0, epochs=0, cache=False)


def test_keras_private_array_data_adapter_still_exists():
    """fit_orders (the fused trainer's batch order) needs Keras's private ArrayDataAdapter; if a Keras
    upgrade moves it, say so here rather than fail deep inside cnn.train."""
    try:
        adapter = cnn._array_data_adapter()
    except ImportError as e:
        pytest.fail(f"keras.src.trainers.data_adapters.array_data_adapter.ArrayDataAdapter is gone "
                    f"in this Keras ({e}); greenloop.cnn._array_data_adapter must follow it, or the "
                    f"fused trainer cannot reproduce model.fit's batch order")
    batches = list(adapter(np.arange(10), batch_size=4, shuffle=True).get_numpy_iterator())
    assert [len(b) for b in batches] == [4, 4, 2], "ArrayDataAdapter no longer yields index batches"
    assert sorted(np.concatenate(batches).tolist()) == list(range(10))
    order = next(cnn.fit_orders(10, 4))
    assert sorted(order.tolist()) == list(range(10))


def _train_in_subprocess(cache):
    X, y = _toy()
    _, h, _ = cnn.train(X, y, seed=5, epochs=2, cache=cache, progress=False)
    return h["val_loss"], h["seconds"]


def test_concurrent_runs_share_one_cache_entry(tmp_path):
    """Two processes asking for the same model at once (make -j2): one trains, the other waits on
    the lock and loads it; the cache holds one complete entry and no temporary folders."""
    import multiprocessing as mp

    with mp.get_context("spawn").Pool(2) as pool:
        a, b = pool.map(_train_in_subprocess, [tmp_path, tmp_path])
    assert a == b  # identical histories, training seconds included: the second one loaded it
    entries = [p for p in tmp_path.iterdir() if p.is_dir()]
    assert len(entries) == 1 and not list(tmp_path.glob(".tmp-*"))


def test_leakage_controls_match_the_training_set_sizes():
    X, y = _toy(n=240, L=60)
    rows = cnn.leakage_controls(X, y, [0], gaps=(0, 10), epochs=1, cache=False, progress=False)
    by = {(r["control"], r["gap"]): r for r in rows}
    assert set(by) == {("blocked", 0), ("random, same n_train", 0), ("blocked", 10),
                       ("random, same n_train", 10), ("blocked, centred", 5)}
    for g in (0, 10):
        assert by["blocked", g]["n_train"] == by["random, same n_train", g]["n_train"]
    assert by["blocked", 0]["n_train"] == 240 - 48 and by["blocked", 10]["n_train"] < 240 - 48
    for r in rows:
        assert r["converged"] == (r["final_train_acc_%"] >= 95) and 0 <= r["test_acc_%"] <= 100


def test_leakage_control_matches_size_within_the_random_split(monkeypatch):
    """Nordland's case: at gap 0 the blocked split of 7152 frames in spots of 60 keeps 5722
    training frames, one more than the random 80/20 split has; the matched random run then keeps
    all 5721 of its own instead of failing."""
    from greenloop import cnn, spots
    y = spots.group(7152, 60)
    asked = []

    def fake_run_seeds(X, y_, seeds, progress=True, **kw):
        out = []
        for s in seeds:
            tr, te = cnn.split_indices(y_, s, split=kw.get("split", "random"), gap=kw.get("gap", 5),
                                       block=kw.get("block", "random"), train_size=kw.get("train_size"))
            asked.append((kw.get("split"), kw.get("train_size"), len(tr)))
            out.append({"seed": s, "split": {"train": tr, "test": te}, "test_accuracy": 0.5,
                        "history": {"accuracy": [1.0]}})
        return out
    monkeypatch.setattr(cnn, "run_seeds", fake_run_seeds)
    rows = cnn.leakage_controls(np.zeros((7152, 1, 1, 1), np.float32), y, [0], gaps=[0])
    blocked, matched = (r for r in rows if r["control"] in ("blocked", "random, same n_train"))
    assert blocked["n_train"] == 5722 and matched["n_train"] == 5721


def _run(seed, test_acc, train_acc, val_acc=(0.5,), n_train=8, n_test=2, seconds=1.25):
    """A run_seeds dict without a model: what the summaries over seeds read."""
    return {"seed": seed, "test_accuracy": test_acc, "split": {"train": np.arange(n_train), "test": np.arange(n_test)},
            "history": {"accuracy": [0.1, train_acc], "val_accuracy": list(val_acc), "seconds": seconds}}


def test_converged_and_first_epoch():
    assert cnn.converged({"accuracy": [0.2, 0.95]}, 0.95) and not cnn.converged({"accuracy": [0.99, 0.94]}, 0.95)
    h = {"val_accuracy": [0.5, 0.97, 0.98, 0.99]}
    assert cnn.first_epoch(h, 0.98) == 3 and cnn.first_epoch(h, 0.5) == 1 and cnn.first_epoch(h, 0.995) is None


def test_accuracy_over_seeds_by_hand():
    runs = [_run(0, 0.90, 0.99), _run(1, 0.80, 0.50), _run(2, 0.70, 0.96)]
    s = cnn.accuracy_over_seeds(runs, converged_at=0.95)
    assert list(s) == ["seeds", "acc_mean_%", "acc_std_%", "acc_median_%", "acc_min_%", "acc_max_%",
                       "final_train_acc_min_%", "converged_seeds", "acc_median_converged_%"]
    assert s["seeds"] == 3 and s["acc_mean_%"] == 80.0 and s["acc_std_%"] == 10.0
    assert (s["acc_median_%"], s["acc_min_%"], s["acc_max_%"]) == (80.0, 70.0, 90.0)
    assert s["final_train_acc_min_%"] == 50.0 and s["converged_seeds"] == 2 and s["acc_median_converged_%"] == 80.0
    one = cnn.accuracy_over_seeds([_run(0, 0.5, 0.2)], converged_at=0.95)
    assert one["acc_std_%"] == 0.0 and one["converged_seeds"] == 0 and np.isnan(one["acc_median_converged_%"])


def test_per_seed_rows_and_seed_summary():
    import pandas as pd

    runs = {"random": [_run(0, 0.9, 0.99, val_acc=(0.5, 0.98, 0.97, 0.99)), _run(1, 0.7, 0.5, val_acc=(0.2, 0.3, 0.4, 0.6))],
            "blocked": [_run(0, 0.4, 0.96, n_train=6, seconds=2.0)]}
    rows = cnn.per_seed_rows(runs, target_accuracy=0.98, converged_at=0.95, after_epoch=2)
    assert [(r["split"], r["seed"]) for r in rows] == [("random", 0), ("random", 1), ("blocked", 0)]
    r0 = rows[0]
    assert list(r0) == ["split", "seed", "n_train", "n_test", "test_acc_%", "epoch_to_98%", "min_val_acc_after_ep2_%",
                        "final_train_acc_%", "converged", "train_seconds"]
    assert r0["epoch_to_98%"] == 2 and r0["min_val_acc_after_ep2_%"] == 97.0 and r0["converged"] is True
    assert rows[1]["epoch_to_98%"] is None and rows[1]["min_val_acc_after_ep2_%"] == 40.0 and rows[1]["converged"] is False
    assert rows[2]["n_train"] == 6 and rows[2]["min_val_acc_after_ep2_%"] == 50.0   # a 1-epoch run: its last epoch
    summ = cnn.seed_summary(pd.DataFrame(rows))
    assert list(summ.columns) == ["split", "seeds", "converged_seeds", "mean", "std", "median", "worst", "best",
                                  "median_of_converged"]
    assert list(summ.split) == ["blocked", "random"]
    rnd = summ.set_index("split").loc["random"]
    assert (rnd.seeds, rnd.converged_seeds, rnd["mean"], rnd["worst"], rnd["best"]) == (2, 1, 80.0, 70.0, 90.0)
    assert rnd["std"] == round(np.std([90, 70], ddof=1), 2) and rnd.median_of_converged == 90.0


def _control_rows():
    import pandas as pd

    rows = []
    for gap, seed, blocked, matched, centred in ((0, 0, 60.0, 80.0, 70.0), (0, 1, 50.0, 90.0, 55.0), (5, 0, 40.0, 45.0, None)):
        for control, acc in zip(cnn.LEAKAGE_CONTROLS, (blocked, matched, centred)):
            if acc is not None:
                rows.append({"control": control, "gap": gap, "seed": seed, "n_train": 100 - 2 * gap + seed,
                             "test_acc_%": acc, "converged": acc > 52})
    return pd.DataFrame(rows)


def test_summarise_controls_gives_the_asked_statistics_only():
    runs = _control_rows()
    s = cnn.summarise_controls(runs, by=["control", "gap"], stats=("mean", "std", "median"))
    assert list(s.columns) == ["control", "gap", "seeds", "converged_seeds", "n_train_median", "acc_mean_%", "acc_std_%",
                               "acc_median_%", "acc_median_converged_%"]
    assert list(zip(s.control, s.gap)) == [("blocked", 0), ("random, same n_train", 0), ("blocked, centred", 0),
                                           ("blocked", 5), ("random, same n_train", 5)]
    b0 = s.iloc[0]
    assert (b0.seeds, b0.converged_seeds, b0.n_train_median, b0["acc_mean_%"], b0["acc_median_converged_%"]) == (2, 1, 100, 55.0, 60.0)
    assert b0["acc_std_%"] == round(np.std([60, 50], ddof=1), 2) and s.iloc[3]["acc_std_%"] == 0.0   # one seed: 0
    assert np.isnan(s.iloc[3]["acc_median_converged_%"])
    t = cnn.summarise_controls(runs, by=["gap", "control"])
    assert list(t.columns)[5:] == ["acc_median_%", "acc_min_%", "acc_max_%", "acc_median_converged_%"]
    assert (t.iloc[0]["acc_min_%"], t.iloc[0]["acc_max_%"]) == (50.0, 60.0)
    with pytest.raises(ValueError):
        cnn.summarise_controls(runs, by=["gap"], stats=("p90",))


def test_memory_points_pairs_runs_of_one_seed_and_gap():
    m = cnn.memory_points(_control_rows())
    assert list(m.columns) == ["memory_points_median", "memory_points_min", "memory_points_max"]
    assert list(m.index) == [("blocked", 0), ("blocked", 5), ("blocked, centred", 0)]
    assert tuple(m.loc[("blocked", 0)]) == (30.0, 20.0, 40.0)        # 80 - 60, 90 - 50
    assert tuple(m.loc[("blocked", 5)]) == (5.0, 5.0, 5.0)
    assert tuple(m.loc[("blocked, centred", 0)]) == (22.5, 10.0, 35.0)


def test_controls_by_grouping_runs_one_gap_per_grouping(monkeypatch):
    asked = []

    def fake(X, y, seeds, gaps, centre_gap, converged_at, progress, **kw):
        asked.append((int(y.max()), list(gaps), centre_gap, converged_at, kw))
        return [{"control": "blocked", "gap": gaps[0], "seed": s} for s in seeds]
    monkeypatch.setattr(cnn, "leakage_controls", fake)
    labels = {20: spots.group(60, 20), 30: spots.group(60, 30)}
    rows = cnn.controls_by_grouping(np.zeros((60, 1, 1, 1), np.float32), labels, [0, 1], gap=5, converged_at=0.9, epochs=3)
    assert asked == [(2, [5], 5, 0.9, {"epochs": 3}), (1, [5], 5, 0.9, {"epochs": 3})]
    assert [(r["frames_per_spot"], r["seed"]) for r in rows] == [(20, 0), (20, 1), (30, 0), (30, 1)]
    assert list(rows[0]) == ["control", "gap", "seed", "frames_per_spot"]
