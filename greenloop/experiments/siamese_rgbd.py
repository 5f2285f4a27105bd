"""Notebook 10's study: Xu 2022's Siamese CNN, three supervisions on RGB, three RGB-D fusions.

One function per table of ``notebooks/10_siamese_rgbd.ipynb``; each returns unrounded values
(AP and R@100P in %, seconds per image), and the notebook rounds them by ``DECIMALS`` where it
writes the tables. The model, its losses, pairs and training stay in :mod:`greenloop.methods.siamese.siamese`.

Every table is scored on the same held-out part of the sequence (:func:`setup`): scikit-learn's
step-wise AP over pairs more than ``exclude`` steps apart whose later frame is held out, with
similarity = 1 - L2 distance / its maximum (a monotone map of Xu 2022's Eq. 5).
"""
from __future__ import annotations

import json
import re
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd

from greenloop import evaluate, features, groundtruth, report, similarity
from greenloop.datasets import sequence
from greenloop.methods.siamese import siamese
from greenloop.study import verdict, wording
from greenloop.util.cache import cache_key

# decimals of the written tables' columns (rounded only where the notebook writes them)
DECIMALS = {"AP_%": 2, "R@100P_%": 2, "AP_mean": 2, "AP_std": 2, "AP_min": 2, "AP_max": 2, "R100P_mean": 2,
            "R100P_min": 2, "R100P_max": 2, "train_s_mean": 1, "extract_ms_per_image": 3, "train_s": 1, "train_cpu_s": 1,
            "s_per_image_batched": 5, "s_per_image_one_at_a_time": 5}
UNRESOLVED = "not resolved: the seed ranges overlap"
LEVELLING = "held-out AP gain, first -> second -> last third of the epochs"
CONVERGED = "networks whose loss stopped falling before their epoch cap"
# the paper's numbers, a reference column only: Table 2 (NYU, AP of mid-level fusion per layer)
# and Table 3 (seconds per image: SCNN CPU and GPU, CNN CPU and GPU, GIST, BoVW)
PAPER_T2 = dict(zip(siamese.LAYERS, [0.7444, 0.7644, 0.8111, 0.7778, 0.7222, 0.7444, 0.6667, 0.6333]))
PAPER_T3 = {"scnn": (0.208, 0.029), "cnn": (0.142, 0.021), "gist": 0.524, "bovw": 1.517}
# the paper's operating points drawn on the PR figures: (recall, precision, legend)
PAPER_POINT_SUPERVISION = (0.83, 0.90, "Xu 2022: precision > 0.90 at 83 % recall (multi-task, New College)")
PAPER_POINT_FUSION = (0.82, 0.92, "Xu 2022: precision 0.92 at 82 % recall (late fusion, NYU)")
SUPERVISION_COLOURS = {"softmax": "C0", "contrastive": "C1", "multitask": "C3"}   # one colour per supervision


class Setup(NamedTuple):
    """What every table of notebook 10 is computed on (frame counts in steps of frame_step).

    info: ``sequence.folder_info``; frames (M,) original frame numbers; exclude_steps: the exclusion band in
    steps; GT (M, M) bool; gap, L: held-out gap and spot length in steps; train, held (M,) bool
    (``siamese.training_split``); split_note: its Markdown note or None; labels (M,) int place
    labels (-1 outside train); X (M, S, S, 3 or 4) float32 inputs in [0, 1]; has_depth;
    chance: the chance AP on the held-out part (a fraction); text: the lines the notebook prints.
    """
    info: dict
    frames: np.ndarray
    exclude_steps: int
    GT: np.ndarray
    gap: int
    L: int
    train: np.ndarray
    held: np.ndarray
    split_note: str | None
    labels: np.ndarray
    X: np.ndarray
    has_depth: bool
    chance: float
    text: str


class Runs(NamedTuple):
    """One table's networks: table (DataFrame, one row per descriptor and seed), sims {(key, seed):
    (M, M) S}, models {(key, seed): descriptor model}, hists {(key, seed): training history},
    trained [(descriptor name with its seed, training seconds, CPU seconds)] in training order."""
    table: pd.DataFrame
    sims: dict
    models: dict
    hists: dict
    trained: list


def setup(dataset, frame_step: int, frames_per_spot: int, loop_threshold: float, exclude: int,
          train_fraction: float, heldout_gap: int, input_size: int, max_depth: float) -> Setup:
    """Frames, ground truth, the training / held-out split, place labels and network inputs.

    dataset: a sequence folder. frame_step: every frame_step-th frame is used. frames_per_spot,
    exclude, heldout_gap: in ORIGINAL frames (converted to steps here, at least 1 for L and the
    gap). loop_threshold: Qi 2024 Eq. 5. train_fraction: share of the revisit frames before the
    cut. input_size: square network input (pixels). max_depth: metres mapped to 1.
    """
    info = sequence.folder_info(dataset)
    frames, exclude_steps, GT, summary = groundtruth.described_frames(dataset, frame_step, loop_threshold, exclude)
    gap = max(1, int(heldout_gap) // int(frame_step))
    L = max(1, int(frames_per_spot) // int(frame_step))
    train, held, note = siamese.training_split(len(frames), train_fraction, GT, gap, L, frames)
    labels = siamese.place_labels(train, GT, L)
    has_depth = bool(info["depth"])
    X = siamese.load_inputs(dataset, (input_size, input_size), step=frame_step, depth=has_depth, max_depth=max_depth)
    chance = evaluate.chance_level(GT, exclude_steps, queries=held)
    rev = groundtruth.revisit_frames(GT)
    text = "\n".join([
        f"Dataset: {info['path']} ({info['kind']}), {info['n_frames']} frames of {info['width']}x{info['height']}, "
        f"depth/: {'yes' if has_depth else 'no'}, trajectory: {'yes' if info['trajectory'] else 'no'}", summary,
        f"training part: frames {frames[train][0]}..{frames[train][-1]} ({int(train.sum())} frames, {labels.max() + 1} "
        f"places of {L} steps, {int((rev & train).sum())} revisit frames); held-out part: frames {frames[held][0]}.."
        f"{frames[held][-1]} ({int(held.sum())} frames, {int((rev & held).sum())} revisit frames); {gap} steps in "
        f"between belong to neither",
        f"inputs {X.shape[1:]} ({'RGB + depth' if has_depth else 'RGB'}); chance AP on the held-out part: "
        f"{100 * chance:.2f} %"])
    return Setup(info, frames, exclude_steps, GT, gap, L, train, held, note, labels, X, has_depth, chance, text)


# ------------------------------------------------------------------------ scoring one network
def score_descriptors(F, GT, exclude: int, queries=None):
    """Xu 2022's matching of descriptors F (N, D): similarity by L2 distance, scored on queries.

    F: (N, D) descriptors; GT: (N, N) bool ground truth; exclude: band in frames of F; queries:
    (N,) bool mask (the held-out part) or None. The similarity is ``similarity.distance_similarity(F,
    normalise=False)`` = 1 - D / max D, monotone in -L2 distance (Eq. 5).
    Returns (S (N, N) float32, AP in %, recall at 100 % precision in %), unrounded.
    """
    S = similarity.distance_similarity(F, normalise=False)
    return (S, 100 * evaluate.average_precision(S, GT, exclude, queries=queries),
            100 * evaluate.recall_at_100_precision(S, GT, exclude, queries=queries))


def _row(descriptor, label, inf, ap, r100, supervision="none", fusion="none", layer="", train_pairs=0,
         epochs=0, train_s=0.0, train_cpu_s=0.0, loaded_from_cache=False, seed=None, converged=None,
         epoch_cap=0) -> dict:
    """One row of notebook 10's tables (AP, R@100P in %; ms per image), unrounded; epochs: the epochs
    the network took, epoch_cap: its most (``siamese_epochs``); converged: ``siamese.converged`` (its
    held-out loss stopped falling within the cap under early stopping, else its training loss within
    its epochs), None when nothing was trained."""
    return {"descriptor": descriptor, "seed": seed, "weights": inf.weights, "label": label, "dim": inf.dim,
            "supervision": supervision, "fusion": fusion, "layer": layer, "train_pairs": train_pairs,
            "epochs": epochs, "epoch_cap": epoch_cap, "converged": converged, "train_s": train_s, "train_cpu_s": train_cpu_s,
            "loaded_from_cache": loaded_from_cache, "AP_%": ap, "R@100P_%": r100,
            "extract_ms_per_image": 1e3 * inf.seconds_per_image}


def heldout_monitor(X, GT, exclude: int, heldout):
    """``siamese.train``'s monitor: (key, fn) with fn(model) = the held-out AP in % of the
    network as it stands (:func:`score_descriptors` on X); watched after every epoch, never used
    to stop or to choose. key names the ground truth, queries and exclusion band in the cache key."""
    key = f"held-out AP %, {cache_key(np.asarray(GT), np.asarray(heldout))}, exclude {int(exclude)}"
    return key, lambda model: score_descriptors(siamese.describe(model, X), GT, exclude, heldout)[1]


def fit_and_score(name: str, X, labels, heldout, gap: int, GT, exclude: int, train_kw: dict, **kw):
    """Train one network (or load it from the cache), check its pairs, describe every frame, score.

    name: the row's descriptor name. X: (N, H, W, C) float32 inputs in [0, 1]; labels: (N,) place
    labels of the training part (-1 elsewhere, ``siamese.place_labels``). heldout: (N,) bool
    queries scored; gap: frames around them no training pair may touch (``siamese.check_pairs``
    raises otherwise). GT, exclude: as :func:`score_descriptors` (GT also keeps negative pairs
    off ground-truth loops and finds the hard negatives). train_kw: ``siamese.train``'s shared
    arguments (seed, epochs, hard_fraction, ...); kw: this network's (supervision, fusion,
    fusion_layer, merge). The held-out AP after every epoch is recorded (:func:`heldout_monitor`).
    Returns (row, S, model, history): row = one dict of notebook 10's tables (AP and R@100P on
    the held-out queries, in %; training seconds; epochs taken and the cap; converged =
    ``siamese.converged``; loaded_from_cache = the model came from the cache, ``util.cache.cached_model``), S (N, N)
    its similarity matrix, the descriptor model, history.
    """
    loaded = []
    model, hist, pairs = siamese.train(X, labels, **train_kw, **kw, gt=GT, monitor=heldout_monitor(X, GT, exclude, heldout),
                                       was_cached=loaded)
    siamese.check_pairs(pairs["pairs"], heldout, gap)   # no held-out frame nor a neighbour within gap
    F, inf = siamese.describe(model, X, return_info=True)
    S, ap, r100 = score_descriptors(F, GT, exclude, heldout)
    row = _row(name, f"{name} ({inf.weights})", inf, ap, r100, kw.get("supervision", "multitask"),
               kw.get("fusion", "none"), kw.get("fusion_layer") or "", len(pairs["pairs"]), len(hist["loss"]),
               hist["seconds"], hist.get("cpu_seconds", float("nan")), loaded[0], train_kw.get("seed"),
               siamese.converged(hist), train_kw["epochs"])
    return row, S, model, hist


def reference_scores(X_rgb, GT, exclude: int, heldout, seeds=(0,), width: float = 1.0):
    """The untrained network (one per seed) and raw pixels on the same held-out queries (Figure 8's
    references).

    X_rgb: (N, H, W, 3) float32 in [0, 1]; GT, exclude, heldout: as :func:`score_descriptors`.
    seeds, width: the untrained ``siamese.embedding``'s initial weights and width (as the trained ones).
    Returns (rows, sims): rows of notebook 10's supervision table ("scnn untrained, RGB" per seed,
    then "pixels (32x32 gray)", seed None) and {("untrained", seed): S, ("pixels", None): S}, (N, N).
    """
    import keras

    rows, sims = [], {}
    for seed in seeds:
        keras.utils.set_random_seed(seed)
        untrained, _ = siamese.embedding(X_rgb.shape[1:], width=width)
        F, inf = siamese.describe(untrained, X_rgb, return_info=True, weights="random init")
        sims["untrained", seed], ap, r100 = score_descriptors(F, GT, exclude, heldout)
        rows.append(_row("scnn untrained, RGB", f"scnn untrained, RGB ({inf.weights})", inf, ap, r100, seed=seed))
    F, inf = features.get("pixels").extract(np.rint(X_rgb * 255).astype(np.uint8))
    sims["pixels", None], ap, r100 = score_descriptors(F, GT, exclude, heldout)
    rows.append(_row("pixels (32x32 gray)", inf.label, inf, ap, r100))
    return rows, sims


def _fit_all(s: Setup, specs, train_kw: dict, X, seeds) -> Runs:
    """fit_and_score for each (key, name, kw) of specs and each seed on inputs X; the table of their
    rows (seed by seed within each spec); sims, models and hists keyed (key, seed)."""
    rows, runs = [], Runs(None, {}, {}, {}, [])
    for key, name, kw in specs:
        for seed in seeds:
            row, S, model, hist = fit_and_score(name, X, s.labels, s.held, s.gap, s.GT, s.exclude_steps,
                                                dict(train_kw, seed=seed), **kw)
            runs.sims[key, seed], runs.models[key, seed], runs.hists[key, seed] = S, model, hist
            runs.trained.append((f"{name}, seed {seed}", hist["seconds"], hist.get("cpu_seconds", float("nan"))))
            rows.append(row)
    return runs._replace(table=pd.DataFrame(rows))


# ------------------------------------------------------------------------------------ tables
def supervisions(s: Setup, supervisions, train_kw: dict, seeds) -> Runs:
    """Figure 8's table: each supervision on RGB over seeds, then the untrained network (each seed)
    and pixels.

    s: :func:`setup`. supervisions: names of ``siamese.SUPERVISIONS``. train_kw: ``siamese.train``'s
    shared arguments but the seed (width also sizes the untrained reference). seeds: ints.
    Returns Runs keyed (supervision, seed), ("untrained", seed) and ("pixels", None).
    """
    X_rgb = s.X[..., :3]
    runs = _fit_all(s, [(sup, f"scnn {sup}, RGB", {"supervision": sup}) for sup in supervisions], train_kw, X_rgb, seeds)
    rows, sims = reference_scores(X_rgb, s.GT, s.exclude_steps, s.held, seeds, train_kw.get("width", 1.0))
    runs.sims.update(sims)
    return runs._replace(table=pd.concat([runs.table, pd.DataFrame(rows)], ignore_index=True))


def _paper_layer(mid_layers) -> str:
    """The paper's best mid-level layer (conv2), or the first of mid_layers without it: fixed in
    advance, never chosen on this data."""
    return "conv2" if "conv2" in mid_layers else mid_layers[0]


def fusions(s: Setup, sup: Runs, fusion_supervision: str, mid_layers, merge: str, train_kw: dict, seeds,
            ranking_seeds=None) -> Runs:
    """Figure 9's and Table 2's table over seeds: RGB only, early, mid-level at each layer, late,
    and each stream of the late network alone; all with ``fusion_supervision``.

    s: :func:`setup`; sup: :func:`supervisions` (its rows of the same supervision are "RGB only").
    mid_layers: layers of ``siamese.LAYERS``; merge: "sum" or "concat"; train_kw, seeds: as
    supervisions. ranking_seeds: the seeds of the arms Xu 2022 ranks (early, mid-level at the paper's
    layer, late, and RGB only: ``sup`` must hold them), so that an order of them can rest on enough
    seeds while the other mid-level layers keep ``seeds`` (default: ``seeds`` for all). Without depth
    the table is three "skipped" rows and nothing is trained.
    """
    if not s.has_depth:
        rows = [{"descriptor": f, "weights": "trained here", "label": f"scnn {f} fusion (trained here)",
                 "status": "skipped: the dataset has no depth/ folder"} for f in ("early", "mid-level", "late")]
        return Runs(pd.DataFrame(rows), {}, {}, {}, [])
    kw, ranked = {"supervision": fusion_supervision}, list(seeds if ranking_seeds is None else ranking_seeds)
    mid = lambda layer: (f"mid {layer}", f"scnn mid-level fusion at {layer}",
                         dict(kw, fusion="mid", fusion_layer=layer, merge=merge))
    paper = _paper_layer(mid_layers)
    first = [("early", "scnn early fusion", dict(kw, fusion="early")), mid(paper)]
    runs = _fit_all(s, first + [("late", "scnn late fusion", dict(kw, fusion="late"))], train_kw, s.X, ranked)
    rest = _fit_all(s, [mid(layer) for layer in mid_layers if layer != paper], train_kw, s.X, seeds)
    for d in ("sims", "models", "hists"):
        getattr(runs, d).update(getattr(rest, d))
    runs.trained.extend(rest.trained)
    order = {f"scnn mid-level fusion at {layer}": k for k, layer in enumerate(mid_layers)}
    table = pd.concat([runs.table, rest.table], ignore_index=True)
    key = table.descriptor.map(lambda d: -1 if d == "scnn early fusion" else order.get(d, len(order)))
    table = table.assign(_k=key).sort_values(["_k", "seed"], kind="stable").drop(columns="_k")
    rows = table.to_dict("records")
    ref = sup.table[(sup.table.supervision == fusion_supervision) & sup.table.seed.isin(ranked)]
    for k, r in enumerate(ref.to_dict("records")):   # the RGB networks of the same supervision, for reference
        rows.insert(k, dict(r, descriptor=f"RGB only ({fusion_supervision})", fusion="RGB only"))
        runs.sims["RGB only", r["seed"]] = sup.sims[fusion_supervision, r["seed"]]
    lates = [r for r in rows if r["fusion"] == "late"]
    for stream in ("rgb", "depth"):          # each stream of the late-fusion networks alone
        key = f"late ({stream} stream)"
        for late in lates:
            seed = late["seed"]
            F = siamese.describe(runs.models["late", seed], s.X, stream=stream)
            runs.sims[key, seed], ap, r100 = score_descriptors(F, s.GT, s.exclude_steps, s.held)
            name = f"scnn late fusion, {stream} stream alone"
            rows.append(dict(late, descriptor=name, label=f"{name} ({late['weights']})", fusion=key,
                             **{"AP_%": ap, "R@100P_%": r100}))
    return runs._replace(table=pd.DataFrame(rows))


def seed_summary(table: pd.DataFrame) -> pd.DataFrame:
    """One row per descriptor of a per-seed table (:func:`supervisions` or :func:`fusions`), in
    order: descriptor, supervision, fusion, layer, seeds, converged_seeds (``siamese.converged``; 0 for
    untrained rows), and the mean, standard deviation (ddof 1;
    NaN for one run), min and max over seeds of AP_% and R@100P_% (AP_mean, AP_std, AP_min,
    AP_max, R100P_mean, R100P_min, R100P_max), the mean train_s, and the fewest and most epochs a
    seed took (epochs_min, epochs_max; 0 for untrained rows). A skipped table (no depth:
    nothing trained) is returned as it is."""
    if "AP_%" not in table:
        return table
    g = table.assign(converged=table["converged"].eq(True) if "converged" in table else False,
                     epochs=table["epochs"] if "epochs" in table else 0).groupby("descriptor", sort=False)
    return g.agg(supervision=("supervision", "first"), fusion=("fusion", "first"), layer=("layer", "first"),
                 seeds=("AP_%", "size"), converged_seeds=("converged", "sum"), AP_mean=("AP_%", "mean"), AP_std=("AP_%", "std"), AP_min=("AP_%", "min"),
                 AP_max=("AP_%", "max"), R100P_mean=("R@100P_%", "mean"), R100P_min=("R@100P_%", "min"),
                 R100P_max=("R@100P_%", "max"), train_s_mean=("train_s", "mean"),
                 epochs_min=("epochs", "min"), epochs_max=("epochs", "max")).reset_index()


def convergence_rule(hists) -> str:
    """The convergence rule the networks of ``hists`` (histories) were judged by, in words
    (``siamese.converged``): the held-out loss under early stopping, else the training loss."""
    if any(h.get("val_loss") for h in hists):
        patience = "/".join(sorted({str(h.get("stop_patience", "?")) for h in hists if h.get("val_loss")}))
        return (f"siamese.converged: early stopping on a held-out loss (pairs of every {siamese.VALIDATION_EVERY}th "
                f"training frame of a place, never trained on) that fell by less than {100 * siamese.STOP_MIN_DELTA:g} % "
                f"of its best for {patience} epochs before the epoch cap")
    return (f"siamese.converged: the training loss fell by less than {100 * siamese.STOP_MIN_DELTA:g} % of its best "
            f"for {siamese.STOP_PATIENCE} epochs before the budget's last epoch (a fixed budget, no early stopping)")


RANKED_FUSIONS = ("early", "late")        # with the paper's mid-level layer: the fusions the verdict orders


def ranked_fusions(table: pd.DataFrame, mid_layers) -> pd.DataFrame:
    """The rows of a fusion table (:func:`fusions`' per-seed table or :func:`seed_summary`'s) whose
    networks the verdict's "late fusion first" counts: early, mid-level at the paper's layer, late."""
    if "fusion" not in table:
        return table
    return table[table.fusion.isin(RANKED_FUSIONS) | ((table.fusion == "mid") & (table.layer == _paper_layer(mid_layers)))]


def converged_networks(*tables: pd.DataFrame) -> tuple[int, int]:
    """(k, n): n networks trained for the per-seed tables given (:func:`supervisions`, :func:`fusions`;
    rows with epochs > 0, each network once: the fusion table's "RGB only" rows and the late
    networks' single-stream rows are networks of other rows), k of them converged (``siamese.converged``)."""
    kept = [x for x in tables if "converged" in x]           # a skipped fusion table trained nothing
    if not kept:
        return 0, 0
    t = pd.concat(kept, ignore_index=True)
    t = t[(t.epochs > 0) & ~t.fusion.isin(["RGB only", "late (rgb stream)", "late (depth stream)"])]
    return int(t.converged.eq(True).sum()), len(t)


def budget_label(*tables: pd.DataFrame) -> str:
    """"budget-limited: k of n networks converged" (:func:`converged_networks`) where fewer than half
    converged (``verdict.budget_limited``), else "": the label the tables' notes, the figures
    (:func:`label_budget`) and the conclusion carry."""
    k, n = converged_networks(*tables)
    return f"budget-limited: {k} of {n} networks converged" if n and verdict.budget_limited(k, n) else ""


def label_budget(fig, *tables: pd.DataFrame):
    """Write :func:`budget_label` in red above the figure (nothing where the networks converged);
    returns the figure."""
    return report.label_figure(fig, budget_label(*tables))


def best_of(summary: pd.DataFrame, names) -> tuple[str | None, str]:
    """The descriptor among ``names`` (rows of :func:`seed_summary`) with the highest mean AP, if
    every arm has at least ``verdict.MIN_SEEDS`` seeds and its lowest seed is above every other's
    highest (the seed ranges separate: the verdict table's rule); else None.
    Returns (name or None, text): text gives each mean and [min, max] over seeds."""
    t = summary.set_index("descriptor").loc[list(names)]
    top = t.AP_mean.idxmax()
    others = t.drop(index=top)
    text = "; ".join(f"{d} {r.AP_mean:.2f} [{r.AP_min:.2f}, {r.AP_max:.2f}]" for d, r in t.iterrows())
    if t.seeds.min() < verdict.MIN_SEEDS:
        return None, text + f" (fewer than {verdict.MIN_SEEDS} seeds per arm)"
    separated = len(others) > 0 and t.loc[top, "AP_min"] > others.AP_max.max()
    return (top if separated else None), text


def timing(s: Setup, sup: Runs, fus: Runs, dataset, fusion_supervision: str, mid_layers,
           timing_frames: int, vocab_size: int = features.DEFAULT_VOCAB_SIZE) -> tuple[pd.DataFrame, int]:
    """Table 3's measurements on this CPU: seconds per image of the networks (batched, and one at
    a time on timing_frames frames) and of SIFT-BoVW (SIFT and quantisation into vocab_size words,
    the vocabulary fitted untimed on the same frames) on up to 64 native frames spread over the
    sequence; each network's first seed. Returns (table, number of native frames SIFT was timed on)."""
    import warnings

    first = {key: m for (key, _), m in reversed(list(sup.models.items()) + list(fus.models.items()))}  # first seed's
    timed = [(f"scnn {fusion_supervision}, RGB", first.get(fusion_supervision, list(first.values())[-1]), s.X[..., :3])]
    if s.has_depth:
        layer = _paper_layer(mid_layers)
        timed += [("scnn early fusion", first["early"], s.X),
                  (f"scnn mid-level fusion at {layer}", first[f"mid {layer}"], s.X),
                  ("scnn late fusion", first["late"], s.X)]
    rows = []
    for name, model, Xin in timed:
        _, batched = siamese.describe(model, Xin, batch_size=256, return_info=True)
        _, single = siamese.describe(model, Xin[:timing_frames], batch_size=1, return_info=True)
        rows.append({"descriptor": name, "weights": batched.weights, "label": f"{name} ({batched.weights})",
                     "input": "x".join(map(str, batched.input_size)), "s_per_image_batched": batched.seconds_per_image,
                     "s_per_image_one_at_a_time": single.seconds_per_image})
    # the first frames of a small real set may hold no keypoint: frames spread over the sequence
    native = sequence.load_frames(dataset, size=None, gray=False, step=max(1, s.info["n_frames"] // 64), limit=64,
                                  dtype=np.uint8, progress=False)
    with warnings.catch_warnings():    # tiny frames may hold fewer SIFT descriptors than words: timing only
        warnings.simplefilter("ignore", UserWarning)
        t_sift = features.get("sift_bovw", vocab_size=vocab_size).extract(native)[1].seconds_per_image
    rows.append({"descriptor": f"sift_bovw (SIFT + {vocab_size}-word quantisation)", "weights": "none",
                 "label": "sift_bovw (none)", "input": f"{s.info['width']}x{s.info['height']}",
                 "s_per_image_batched": t_sift,
                 "s_per_image_one_at_a_time": t_sift})
    return pd.DataFrame(rows), len(native)


def _range(values, fmt=".2f") -> str:
    """'mean [min, max]' of a 1-D array of per-seed values."""
    v = np.asarray(values, dtype=float)
    return f"{v.mean():{fmt}} [{v.min():{fmt}}, {v.max():{fmt}}]"


def _precision_at(runs: Runs, key, recall: float, s: Setup) -> str:
    """The precision at ``recall`` of each seed's network ``key``, as 'mean [min, max]'."""
    return _range([evaluate.precision_at_recall(S, s.GT, recall, s.exclude_steps, queries=s.held)
                   for (k, _), S in runs.sims.items() if k == key], ".3f")


def _learning(runs: Runs, keys) -> str:
    """'key a -> b (loss c -> d)' per key: the held-out AP after the first and the last epoch and the
    training loss of the first and the last epoch, each a mean over the seeds of runs.hists (each seed's
    last epoch its own: under early stopping the seeds stop apart)."""
    out = []
    for key in keys:
        hs = [h for (k, _), h in runs.hists.items() if k == key]
        m0, m1 = np.mean([h["monitor"][0] for h in hs]), np.mean([h["monitor"][-1] for h in hs])
        l0, l1 = np.mean([h["loss"][0] for h in hs]), np.mean([h["loss"][-1] for h in hs])
        out.append(f"{key} {m0:.2f} -> {m1:.2f} (loss {l0:.3g} -> {l1:.3g})")
    return "; ".join(out)


def _levelling(hists) -> str:
    """How far the held-out AP levels off: each network's AP after every epoch (history["monitor"],
    %) averaged over the first, second and last third of its epochs; the gains from the first to
    the second third and from the second to the last, in points, each a mean over the networks
    (one network trained for two tables counts once), and how many still gain in the last third."""
    ms = {tuple(h["monitor"]) for h in hists if len(h.get("monitor", ())) >= 3}
    if not ms:
        return "n/a (fewer than 3 epochs watched)"
    thirds = np.array([[np.mean(p) for p in np.array_split(np.array(m), 3)] for m in ms])   # (networks, 3)
    d = np.diff(thirds, axis=1)
    return (f"{d[:, 0].mean():+.1f} then {d[:, 1].mean():+.1f} points over {len(ms)} networks "
            f"({int((d[:, 1] > 0).sum())} still gaining in the last third)")


def _supervision_rows(s: Setup, sup: Runs, supervisions) -> list:
    summ = seed_summary(sup.table).set_index("descriptor")
    names = [f"scnn {x}, RGB" for x in supervisions]
    best, text = best_of(summ.reset_index(), names)
    refs = summ.loc[["scnn untrained, RGB", "pixels (32x32 gray)"]]
    ceiling = refs.AP_max.max()
    beats = [f"{x}: {'above both' if summ.loc[n, 'AP_min'] > ceiling else 'not separated'}"
             for x, n in zip(supervisions, names)]
    seeds = int(summ.loc[names, "seeds"].min())
    rows = [("best supervision", "multi-task (New College)", best or UNRESOLVED,
             f"AP % over {seeds} seeds, mean [min, max]: {text}; held-out part"),
            ("each supervision above the untrained network and raw pixels", "(the paper pretrains; no such control)",
             "; ".join(beats), f"a supervision's lowest seed above the highest of untrained "
             f"{_range(sup.table[sup.table.descriptor == 'scnn untrained, RGB']['AP_%'])} % and pixels "
             f"{summ.loc['pixels (32x32 gray)', 'AP_mean']:.2f} %; chance {100 * s.chance:.2f} %")]
    rows.append(("held-out AP after the first -> the last epoch, per supervision (%)", None, _learning(sup, supervisions),
                 "mean over seeds (convergence figure); the training loss, first -> last epoch, in brackets"))
    if any(k == "multitask" for k, _ in sup.sims):
        rows.append(("precision at 83 % recall, multi-task", "> 0.90", _precision_at(sup, "multitask", 0.83, s),
                     "mean [min, max] over seeds; New College vs the held-out part here"))
    return rows


def _fusion_rows(s: Setup, fus: Runs, mid_layers, merge: str, dataset) -> tuple[list, list]:
    if not s.has_depth:
        why = f"{dataset} has no depth/ folder"
        return ([("RGB-D fusion (Figure 9, Table 2)", "late fusion best", "skipped", why)],
                [(f"AP, mid-level fusion at {layer}", PAPER_T2.get(layer), "skipped", why) for layer in mid_layers])
    summ = seed_summary(fus.table)
    by = summ.set_index("descriptor")
    mids = [f"scnn mid-level fusion at {layer}" for layer in mid_layers]
    t2 = [(f"AP, mid-level fusion at {layer}", PAPER_T2.get(layer), float(by.loc[m, "AP_mean"] / 100),
           f"mean of {int(by.loc[m, 'seeds'])} seeds, [min, max] = [{by.loc[m, 'AP_min'] / 100:.4f}, "
           f"{by.loc[m, 'AP_max'] / 100:.4f}]; {merge}; paper: NYU, Places-pretrained", 4)
          for layer, m in zip(mid_layers, mids)]
    layer_best, layer_text = best_of(summ, mids)
    paper_mid = f"scnn mid-level fusion at {_paper_layer(mid_layers)}"
    fusion_best, fusion_text = best_of(summ, ["scnn early fusion", paper_mid, "scnn late fusion"])
    rgb = f"RGB only ({summ.supervision.iloc[0]})"
    depth_best, depth_text = best_of(summ, [rgb, "scnn late fusion"]) if rgb in by.index else (None, "n/a")
    cmp = [("best mid-level layer (Table 2)", "conv2 (AP 0.8111)",
            layer_best.rsplit(" ", 1)[-1] if layer_best else UNRESOLVED, f"AP % mean [min, max]: {layer_text}"),
           ("best fusion", "late", fusion_best or UNRESOLVED,
            f"AP % mean [min, max]: {fusion_text} (mid-level at the paper's layer, fixed in advance)"),
           ("precision at 82 % recall, late fusion", 0.92, _precision_at(fus, "late", 0.82, s),
            "mean [min, max] over seeds; NYU vs the held-out part here"),
           ("late fusion vs RGB only", "depth helps", depth_best or UNRESOLVED,
            f"AP % mean [min, max]: {depth_text}; depth stream alone "
            f"{by.loc['scnn late fusion, depth stream alone', 'AP_mean']:.2f} %")]
    return cmp, t2


def _timing_rows(tim: pd.DataFrame) -> list:
    tt = tim.set_index("descriptor")
    cpu = report.cpu_model()
    rows = [(f"extraction time per image, CPU (s): {d}",
             PAPER_T3["scnn"][0] if d.startswith("scnn") else PAPER_T3["bovw"],
             f"{tt.loc[d, 's_per_image_one_at_a_time']:.5f} one at a time; "
             f"{tt.loc[d, 's_per_image_batched']:.5f} batched",
             f"{tt.loc[d, 'label']}; input {tt.loc[d, 'input']}; {cpu}"
             + ("; paper: 227x227 AlexNet-size SCNN, Caffe" if d.startswith("scnn") else "; paper: BoVW, Matlab"))
            for d in tt.index]
    return rows + [("extraction time per image, GPU (s): SCNN", PAPER_T3["scnn"][1], "not measured",
                    "no GPU on this machine"),
                   ("extraction time per image, CPU (s): CNN (AlexNet)", PAPER_T3["cnn"][0], "not run",
                    "no AlexNet with Places weights here"),
                   ("extraction time per image, CPU (s): GIST", PAPER_T3["gist"], "not run",
                    "GIST is not in greenloop.features")]


def paper_vs_run(s: Setup, sup: Runs, fus: Runs, tim: pd.DataFrame, supervisions, mid_layers, merge: str,
                 dataset) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """The paper's numbers beside this run's: (paper_vs_run, Table 2, Table 3) as
    ``report.paper_vs_run`` tables. A supervision, layer or fusion is named best only where its
    seed range lies above every other's (:func:`best_of`), else :data:`UNRESOLVED`; the means and
    ranges stand beside it."""
    cmp, t2 = _fusion_rows(s, fus, mid_layers, merge, dataset)
    k, n = converged_networks(sup.table, fus.table)
    level = [(LEVELLING, None, _levelling(list(sup.hists.values()) + list(fus.hists.values())),
              "every network trained here, its held-out AP averaged per third of its epochs (convergence figure)"),
             (CONVERGED, "trained until the validation accuracy stalls for 10 epochs",
              f"{k} of {n}" + (f" ({budget_label(sup.table, fus.table)})" if budget_label(sup.table, fus.table) else ""),
              convergence_rule(list(sup.hists.values()) + list(fus.hists.values()))),
             ("epochs taken per network, min - median - max", None, _epochs(sup.table, fus.table), "of each one's cap")]
    return (report.paper_vs_run(_supervision_rows(s, sup, supervisions) + level + cmp), report.paper_vs_run(t2),
            report.paper_vs_run(_timing_rows(tim)))


def _epochs(*tables: pd.DataFrame) -> str:
    """The epochs the networks of the per-seed tables took (each network once, as
    :func:`converged_networks` counts them), 'min - median - max (cap C)'."""
    t = pd.concat([x for x in tables if "epochs" in x], ignore_index=True)
    t = t[(t.epochs > 0) & ~t.fusion.isin(["RGB only", "late (rgb stream)", "late (depth stream)"])]
    if not len(t):
        return "n/a"
    caps = "/".join(str(int(c)) for c in sorted(t.epoch_cap.unique())) if "epoch_cap" in t else "?"
    return f"{int(t.epochs.min())} - {t.epochs.median():g} - {int(t.epochs.max())} (cap {caps})"


def _supervision_sentence(sup: pd.DataFrame, chance: float, dataset: str) -> str:
    """Training buys something (the condition for reading Figure 8): each supervision's held-out AP
    over seeds (supervisions.csv, %) against the untrained network's and raw pixels'."""
    t = sup.set_index("descriptor")
    untrained, pixels = t.loc["scnn untrained, RGB"], t.loc["pixels (32x32 gray)"]
    ceiling = max(untrained.AP_max, pixels.AP_max)
    parts = [f"{r.supervision} {wording.span(r.AP_min, r.AP_max)}"
             + (" (every seed above both)" if r.AP_min > ceiling else " (not separated from them)")
             for _, r in t[t.supervision.isin(["softmax", "contrastive", "multitask"])].iterrows()]
    n = int(t.seeds.max())
    few = f"; with fewer than {verdict.MIN_SEEDS} seeds per arm none of this is an order" if n < verdict.MIN_SEEDS else ""
    return (f"On {dataset}, held-out AP (%, [min, max] over {n} seeds): " + ", ".join(parts) + f", against the "
            f"untrained network's {wording.span(untrained.AP_min, untrained.AP_max)} and raw pixels' "
            f"{wording.num(pixels.AP_max)} (chance {wording.num(100 * chance)}){few}.")


def _reached(cell: str, paper: float) -> str:
    """'reached by no seed' / 'reached by the best seed' for a 'mean [min, max]' cell against a claimed
    value ``paper`` (same unit); the cell itself where it holds no range."""
    m = re.match(r"\s*[-\d.]+ \[([-\d.]+), ([-\d.]+)\]", str(cell))
    if not m:
        return str(cell)
    return f"{cell}, {'reached by the best seed' if float(m.group(2)) >= paper else 'reached by no seed'}"


def _budget_sentence(run: pd.Series) -> str:
    """The budget label where fewer than half of the networks converged, how far the budget levels off
    and the precision at the paper's recall (paper_vs_run.csv's cells)."""
    m = re.search(r"budget-limited: \d+ of \d+ networks converged", str(run.get(CONVERGED, "")))
    text = (f"**{m[0][0].upper() + m[0][1:]}** (the others' loss still fell when they reached their epoch cap), "
            f"so every AP and order here is the budget's. " if m else "")
    if "epochs taken per network, min - median - max" in run.index:
        text += f"Epochs taken per network, min - median - max: {run['epochs taken per network, min - median - max']}. "
    text += f"Held-out AP gained from the first to the second third of the epochs, then to the last: {run[LEVELLING]}."
    p83 = "precision at 83 % recall, multi-task"
    if p83 in run.index:
        text += f" Multi-task's precision at 83 % recall, mean [min, max]: {_reached(run[p83], 0.90)} (paper: > 0.90, New College)"
        p82 = "precision at 82 % recall, late fusion"
        text += (f"; late fusion's at 82 %: {_reached(run[p82], 0.92)} (paper: 0.92, NYU)." if p82 in run.index else ".")
    return text


def _layer_sentence(fus: pd.DataFrame) -> str:
    """Table 2's claim, conv2 the best mid-level layer, by ``study.verdict.rank_verdict`` on the mid-level
    rows of fusions.csv (AP %, [min, max] over seeds); "" without depth."""
    if "fusion" not in fus or "conv2" not in set(fus[fus.fusion == "mid"].layer):
        return ""
    mid = fus[fus.fusion == "mid"]
    arms = {r.layer: (r.seeds, r.AP_min, r.AP_max) for r in mid.itertuples()}
    return (f"Mid-level fusion at each layer, AP [min, max]: " + ", ".join(f"{k} {wording.span(v[1], v[2])}" for k, v in arms.items())
            + f"; conv2 first (Table 2): {verdict.rank_verdict('conv2', arms)}.")


def _timing_sentence(tim: pd.DataFrame) -> str:
    """Table 3's SCNN against SIFT-BoVW, one timing each (timing.csv, s per image one at a time)."""
    t = tim.set_index("descriptor")["s_per_image_one_at_a_time"]
    net, sift = t.index[0], t.index[-1]
    return (f"Seconds per image one at a time on this CPU: {net} {t[net]:.5f}, SIFT-BoVW {t[sift]:.5f} (a "
            f"{max(t[net], t[sift]) / min(t[net], t[sift]):.0f}x ratio; one timing each, {wording.NOT_A_RANKING}; "
            "the network here is a trunk scaled down to 2 CPU cores, not the paper's AlexNet).")


def conclusion(out_dir) -> str:
    """Notebook 10's last cell, in Markdown: the verdicts on Xu 2022's claims for this dataset
    (``study.verdict``: multi-task first, late fusion first, depth helps), then what this run's tables
    under ``out_dir`` (supervisions, fusions, paper_vs_run, timing, summary.json) say: whether training
    lifts the networks above the untrained one and pixels, how far the budget levels off, the
    precision at the paper's recall, conv2 among the layers and Table 3's timing. AP in %."""
    out_dir = Path(out_dir)
    read = lambda name: pd.read_csv(out_dir / name)
    chance = json.loads((out_dir / "summary.json").read_text())["chance_ap"]
    run = read("paper_vs_run.csv").set_index("quantity")["this run"]
    lines = [_supervision_sentence(read("supervisions.csv"), chance, verdict.dataset_name(out_dir.parent)),
             _budget_sentence(run), _layer_sentence(read("fusions.csv")), _timing_sentence(read("timing.csv"))]
    return wording.heading(Path(out_dir).parent, "10_siamese_rgbd") + "\n\n" + " ".join(x for x in lines if x)


def note(s: Setup, frame_step: int, dataset) -> str:
    """The tables' note: how AP is scored, on which frames, what the weights mean."""
    f, held, train = s.frames, s.held, s.train
    return (f"AP = sklearn step-wise average precision over pairs > {s.exclude_steps} steps ({s.exclude_steps * frame_step} original frames) "
            f"apart whose later frame is in the held-out part ({int(held.sum())} frames from frame {f[held][0]}); "
            f"similarity = -L2 distance of the fc7 descriptors; {len(f)} frames (frame_step {frame_step}) of "
            f"{dataset}; weights: 'trained here' = trained in this run on the training part (frames "
            f"{f[train][0]}..{f[train][-1]}), 'random init' = untrained; chance AP {100 * s.chance:.2f} %.")


def summary(s: Setup, sup_table, fusion_table, timing_table, frame_step: int, trained) -> dict:
    """summary.json's content but notebook_seconds: the tables' records (as given), the split's
    frame counts, and the training seconds of every network (trained: Runs.trained lists)."""
    near = siamese.near_heldout(s.held, s.gap)          # held-out frames and their neighbours within gap
    return {"supervisions": sup_table.to_dict("records"), "fusions": fusion_table.to_dict("records"),
            "timing": timing_table.to_dict("records"), "frames": len(s.frames), "frame_step": frame_step,
            "exclude_steps": s.exclude_steps, "gap_steps": s.gap, "spot_steps": s.L, "places": int(s.labels.max() + 1),
            "train_frames": int(s.train.sum()), "heldout_frames": int(s.held.sum()),
            "first_heldout_frame": int(s.frames[s.held][0]), "last_train_frame": int(s.frames[s.train][-1]),
            "labelled_frames_near_heldout": int(((s.labels >= 0) & near).sum()), "chance_ap": s.chance,
            "has_depth": s.has_depth, "networks_trained": len(trained),
            "training_seconds": {t[0]: t[1] for t in trained}, "training_cpu_seconds": {t[0]: t[2] for t in trained},
            "training_cpu_seconds_total": float(sum(t[2] for t in trained)),
            "training_seconds_total": float(sum(t[1] for t in trained))}


# ----------------------------------------------------------------------------------- figures
def _pr_axes(ax, chance, label=None, paper=None):
    """Recall / precision axes with chance as a dotted line and, where given, the paper's operating
    point paper = (recall, precision, legend) as an open black marker with its legend entry."""
    ax.axhline(chance, color="k", lw=0.6, ls=":", label=label)
    if paper is not None:
        ax.plot(paper[0], paper[1], marker="D", ms=9, mfc="none", mec="k", ls="none", label=paper[2])
    ax.set_xlabel("recall"); ax.set_ylabel("precision"); ax.set_xlim(0, 1); ax.set_ylim(0, 1.02); ax.grid(alpha=0.3)


def figure_supervisions(s: Setup, sup: Runs, supervisions, dataset):
    """Figure 8's layout: PR curves of each supervision and the untrained network (every seed, the first
    thicker) and pixels; the legend gives each one's AP over seeds as mean [min, max]."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 5.5))
    summ = seed_summary(sup.table).set_index("descriptor")
    curves = [(x, f"scnn {x}, RGB", "-", SUPERVISION_COLOURS.get(x, f"C{k + 4}"), 1.6) for k, x in enumerate(supervisions)]
    curves += [("untrained", "scnn untrained, RGB", "-", "0.5", 1), ("pixels", "pixels (32x32 gray)", "-", "C2", 1)]
    for key, name, ls, colour, lw in curves:
        r_ = summ.loc[name]
        spread = f" [{r_.AP_min:.1f}, {r_.AP_max:.1f}] over {int(r_.seeds)} seeds" if r_.seeds > 1 else ""
        _seed_curves(ax, s, sup, key, colour, ls, lw, f"{name}: AP {r_.AP_mean:.1f} %{spread}")
    _pr_axes(ax, s.chance, f"chance ({100 * s.chance:.1f} %)", PAPER_POINT_SUPERVISION)
    ax.set_title(f"Figure 8 layout: supervisions, RGB, held-out part of {Path(dataset).name} "
                 f"({int(s.held.sum())} query frames; every seed's curve)", fontsize=10)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0)
    return fig


def _seed_curves(ax, s: Setup, runs: Runs, key, colour, ls, lw, label) -> None:
    """Every seed's PR curve of ``key`` in runs.sims on ax, the first labelled, the others thinner."""
    for n, ((k, seed), S) in enumerate((x for x in runs.sims.items() if x[0][0] == key)):
        p, r, _ = evaluate.pr_curve(S, s.GT, s.exclude_steps, queries=s.held)
        ax.plot(r, p, ls, color=colour, lw=lw if n == 0 else 0.7 * lw, alpha=1 if n == 0 else 0.45,
                label=label if n == 0 else None)


def fusion_header(fus: Runs, mid_layers) -> str:
    """Figure 9's count: how many of the networks the verdict's "late fusion first" counts (early,
    mid-level at the paper's layer, late: :func:`ranked_fusions`) converged (``siamese.converged``)."""
    k, n = converged_networks(ranked_fusions(fus.table, mid_layers))
    return (f"early, mid-level at {_paper_layer(mid_layers)} and late fusion: {k} of {n} networks converged"
            + (" (budget-limited)" if n and verdict.budget_limited(k, n) else ""))


def figure_fusions(s: Setup, fus: Runs, mid_layers, merge: str, fusion_supervision: str, dataset):
    """Figure 9's layout (left) and mid-level fusion at each layer (right): every seed's PR curve
    (the first labelled and drawn thicker), AP over seeds in the legends, and above them
    :func:`fusion_header`; a note without depth. Returns (figure, file stem):
    "figure9_fusions" or "figure9_skipped"."""
    import matplotlib.pyplot as plt

    if not s.has_depth:
        fig, ax = plt.subplots(figsize=(6, 1.5)); ax.axis("off")
        ax.text(0.5, 0.5, f"RGB-D fusion skipped:\n{dataset} has no depth/ folder", ha="center", va="center")
        return fig, "figure9_skipped"
    fig, axes = plt.subplots(1, 2, figsize=(14, 5.6))
    summ = seed_summary(fus.table)
    row = {r.fusion if r.fusion != "mid" else f"mid {r.layer}": r for r in summ.itertuples()}
    show = [("RGB only", "C0", ":"), ("late (depth stream)", "C2", ":"), ("early", "C1", "--"),
            (f"mid {_paper_layer(mid_layers)}", "C4", "-."), ("late", "C3", "-")]
    for key, colour, ls in [x for x in show if x[0] in row]:
        x = row[key]
        _seed_curves(axes[0], s, fus, key, colour, ls, 1.6,
                     f"{x.descriptor}: AP {x.AP_mean:.1f} % [{x.AP_min:.1f}, {x.AP_max:.1f}], {int(x.seeds)} seeds")
    axes[0].set_title(f"Figure 9 layout: fusions ({fusion_supervision}), held-out part, every seed's curve", fontsize=10)
    cmap = plt.get_cmap("viridis")
    for k, layer in enumerate(mid_layers):
        x = row[f"mid {layer}"]
        _seed_curves(axes[1], s, fus, f"mid {layer}", cmap(k / max(1, len(mid_layers) - 1)), "-", 1.2,
                     f"at {layer}: AP {x.AP_mean:.1f} % [{x.AP_min:.1f}, {x.AP_max:.1f}], {int(x.seeds)} seeds")
    axes[1].set_title(f"mid-level fusion at each layer ({merge}), held-out part, every seed's curve", fontsize=10)
    axes[1].legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=3, borderaxespad=0)
    _pr_axes(axes[0], s.chance, paper=PAPER_POINT_FUSION)
    _pr_axes(axes[1], s.chance)
    axes[0].legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=1, borderaxespad=0)
    fig.suptitle(fusion_header(fus, mid_layers), fontsize=11)
    fig.tight_layout()
    return fig, "figure9_fusions"


def figure_convergence(sup: Runs, fus: Runs, mid_layers, has_depth: bool):
    """Did the budget converge? Per epoch and seed: the training loss of each supervision (left),
    its held-out AP (middle, with the untrained networks' and raw pixels' AP as lines), and the
    held-out AP of the early, paper-layer mid-level and late fusions (right). The held-out AP is
    watched only: the budget is fixed in advance."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(16, 4))
    colours = {}
    for (key, seed), h in sup.hists.items():
        c = colours.setdefault(key, SUPERVISION_COLOURS.get(key, f"C{len(colours) + 4}"))
        ep = np.arange(1, len(h["loss"]) + 1)
        label = key if seed == next(sd for k, sd in sup.hists if k == key) else None
        axes[0].plot(ep, h["loss"], color=c, lw=1, label=label)
        if h.get("val_loss"):                   # early stopping's held-out loss, dashed
            axes[0].plot(ep[:len(h["val_loss"])], h["val_loss"], color=c, lw=0.8, ls="--",
                         label=f"{key}, held-out loss" if label else None)
        axes[1].plot(ep, h["monitor"], color=c, lw=1, label=label)
    t = sup.table.set_index("descriptor")
    axes[1].axhline(t.loc[["scnn untrained, RGB"], "AP_%"].max(), color="0.5", ls="--", lw=1, label="untrained (best seed)")
    axes[1].axhline(t.loc["pixels (32x32 gray)", "AP_%"], color="k", ls=":", lw=1, label="pixels")
    keys = ["early", f"mid {_paper_layer(mid_layers)}", "late"] if has_depth else []
    for k, key in enumerate(keys):
        for n, ((kk, seed), h) in enumerate((x for x in fus.hists.items() if x[0][0] == key)):
            axes[2].plot(np.arange(1, len(h["monitor"]) + 1), h["monitor"], color=f"C{k + 3}", lw=1,
                         label=key if n == 0 else None)
    titles = ["training loss, held-out loss dashed where it stops training", "held-out AP % per epoch, RGB",
              "held-out AP % per epoch, RGB-D" if has_depth else "RGB-D: skipped (no depth/)"]
    for ax, title, ylabel in zip(axes, titles, ["training loss (log scale)", "held-out AP (%)", "held-out AP (%)"]):
        ax.set_title(title + " (one line per seed)" * bool(ax.lines), fontsize=10)
        ax.set_xlabel("epoch"); ax.set_ylabel(ylabel); ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.15), ncol=3, borderaxespad=0)
    axes[0].set_yscale("log")
    fig.tight_layout()
    return fig
