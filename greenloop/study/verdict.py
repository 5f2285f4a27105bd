"""Does each paper's headline claim hold here? One row per claim, one cell per dataset, read from the tables.

``python -m greenloop verdict [--out results/verdict.md] [--readme README.md] RESULTS...``
(``make readme``) reads the committed tables of each results folder (``results`` for the synthetic
sequence, ``results/nordland``, ``results/gardenspoint``) and writes, per claim of :data:`CLAIMS`,
the paper's value, the measured value with its spread, and a verdict, into ``results/verdict.csv``,
``results/verdict.md`` and the README's ``<!-- verdict:start -->`` block. Nothing is typed by hand:
a claim whose table is missing from a folder reads "not run".

The verdicts (:data:`RULES`, printed under the table, written from the constants the readers judge by):

* **holds** / **does not hold**: a claimed value is reached / missed by the median of the converged
  seeds (the statistic the cell shows, with every seed's range; never the best seed); a single untrained
  measurement (speed) as measured; the dictionary's closure precision against
  :data:`DICTIONARY_PRECISION`. A claimed order is resolved in the claimed / the opposite direction.
* **budget-limited**: fewer than half of the seeds converged (``convergence.CONVERGED``, one definition
  per model family; a spot CNN run counted by ``convergence.spot_cnn_convergence`` on its own table).
* **not resolved**: a value from fewer than :data:`MIN_SEEDS` trained seeds; a claimed order whose arms
  have fewer than :data:`MIN_SEEDS` seeds, or whose seed ranges overlap, or a comparison of single
  values with no spread. With 5 seeds per arm, ranges that do not overlap are a one-sided Mann-Whitney
  U of 0, p = 1/252; the rule is conservative: overlapping ranges can still differ by a rank test.
* **not testable here**: the claim is about networks with no ImageNet weights here (random-init rows
  are never evidence for or against a paper's ranking), or needs data the folder lacks (depth).

Where a folder holds them, newer tables are read instead of the older ones (folders written before
them read as before): Zhang 2017's whitening, the ZCA median filter and Qi's depth from notebooks 08
and 09's ``paired.csv`` (:func:`paired_verdict` on the AUC-PR difference over the same queries, the
network with ImageNet weights); the dictionary from notebook 05's ``seeds_summary.csv`` (each seed's
CNN, :func:`dictionary_over_seeds`); Xu 2022's networks counted by notebook 10's per-seed
``converged`` column with the epochs taken (:func:`xu_networks`).
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Callable, NamedTuple

import pandas as pd

from greenloop.report import fill_block
from greenloop.study import provenance, summary, targets
from greenloop.study.convergence import (CONVERGED, CONVERGED_AT, Convergence, between, converged_flags,
                                         spot_cnn_convergence, training_text)
from greenloop.study.convergence import fmt as _g, parameters as _parameters, read_table as _csv
from greenloop.util.files import write_atomic

MIN_SEEDS = 5
HOLDS, FAILS, BUDGET, UNRESOLVED, UNTESTABLE, NOT_RUN = (
    "holds", "does not hold", "budget-limited", "not resolved", "not testable here", "not run")
DATASETS = {"synthetic-greenhouse": "synthetic", "nordland": "Nordland", "gardenspoint": "Gardens Point"}
DICTIONARY_PRECISION = targets.PRECISION_TARGET     # % closure precision the dictionary's row asks
RULES = (
    f"holds / does not hold (a claimed value): the median of the converged seeds (shown in the cell, with the seeds' "
    f"range) reaches / misses the paper's value, the same statistic in every row, never the best seed; a single "
    f"untrained measurement (speed) is judged as measured; the dictionary's value is its closure precision, which must "
    f"reach {DICTIONARY_PRECISION:g} % (the paper gives none; the detector targets' bar). holds / does not hold (a "
    f"claimed order): resolved for / against the paper. budget-limited: fewer than half of the seeds converged. "
    f"not resolved: a value from fewer than {MIN_SEEDS} trained seeds; an order with fewer than {MIN_SEEDS} seeds per "
    f"arm, overlapping seed ranges, or single values without spread (with 5 seeds per arm, separate ranges are a "
    f"one-sided Mann-Whitney U of 0, p = 1/252). not testable here: networks without ImageNet weights here, or data "
    f"the folder lacks. A claimed order read from a paired interval (a minus b on the same queries): "
    f"holds / does not hold where it excludes 0; {UNRESOLVED} ({targets.TIE}) where both ends are exactly 0, "
    f"({targets.UNINFORMATIVE}) where one end lands exactly on 0 (a bootstrap over few blocks). "
    f"Converged, per model family: "
    + "; ".join(f"{k}: {v}" for k, v in CONVERGED.items()) + ".")


def budget_limited(converged: int, seeds: int) -> bool:
    """The one rule for "budget-limited" (tables, figures, verdicts): fewer than half of the ``seeds``
    runs converged (``converged`` of them did: ``training_over_seeds.converged``)."""
    return bool(2 * converged < seeds)


def value_verdict(paper: float, median: float | None, conv: Convergence, higher_is_better=True) -> str:
    """Verdict on a claimed value (:data:`RULES`): budget-limited where fewer than half of the seeds
    converged; not resolved with fewer than :data:`MIN_SEEDS` seeds; else the ``median`` of the
    converged seeds (same unit as ``paper``) reaches it or not."""
    if budget_limited(conv.converged, conv.seeds) or median is None:
        return BUDGET
    if conv.seeds < MIN_SEEDS:
        return f"{UNRESOLVED} ({conv.seeds} trained seed{'s' * (conv.seeds != 1)}, no spread)"
    reached = median >= paper if higher_is_better else median <= paper
    return HOLDS if reached else FAILS


def converged_median(values: pd.Series, flags: pd.Series, unit: str = "") -> tuple[str, float | None]:
    """(cell text, statistic): the median of ``values`` over the seeds whose ``flags`` are True (the
    statistic every value row judges), with every seed's range beside it; None where none converged."""
    conv = values[flags.values]
    med = float(conv.median()) if len(conv) else None
    head = (f"median of the converged seeds {_g(med)}{unit}" if med is not None
            else f"no converged seed (median of all {_g(values.median())}{unit})")
    return f"{head}, all seeds [{_g(values.min())}, {_g(values.max())}]{unit}", med


def rank_verdict(claimed: str, arms: dict[str, tuple[int, float, float]]) -> str:
    """Verdict on "``claimed`` ranks first": ``arms`` maps each arm to (seeds, min, max) of its metric.
    holds: every arm has >= MIN_SEEDS seeds and the claimed arm's min lies above every other's max;
    does not hold: as many seeds and some other arm's min lies above the claimed arm's max; not run
    where the run has no ``claimed`` arm (a notebook run with fewer supervisions or layers)."""
    if claimed not in arms:
        return f"{NOT_RUN} ({claimed} not in this run)"
    n, lo, hi = arms[claimed]
    others = {k: v for k, v in arms.items() if k != claimed}
    if min([n] + [v[0] for v in others.values()]) < MIN_SEEDS:
        return f"{UNRESOLVED} (fewer than {MIN_SEEDS} seeds per arm)"
    if all(lo > v[2] for v in others.values()):
        return HOLDS
    if any(v[1] > hi for v in others.values()):
        return FAILS
    return f"{UNRESOLVED} (seed ranges overlap)"


def paired_verdict(lo: float, hi: float) -> str:
    """Verdict on a claimed "a above b" from the paired interval [lo, hi] of a minus b (points, the
    same queries): holds / does not hold where it excludes 0; else not resolved, saying whether it is
    a tie or uninformative (``targets.paired_word``'s one rule) or holds 0 inside."""
    word = targets.paired_word(lo, hi)
    if word == targets.RESOLVED:
        return HOLDS if lo > 0 else FAILS
    return f"{UNRESOLVED} ({'the paired interval holds 0' if word == targets.NOT_RESOLVED else word})"


PAIRED_METRIC = "AUC-PR"       # the metric of paired.csv (notebooks 08, 09) the orders are judged on (per query, %)


def paired_row(folder: Path, notebook: str, comparison: str, backbone: str | None = None):
    """The :data:`PAIRED_METRIC` row of ``comparison`` in ``<notebook>/paired.csv`` (a minus b on the
    same queries, points) for the first network with ImageNet weights (``weights == "imagenet"``; or
    that ``backbone``), or None where the folder has no such table or row."""
    t = _csv(folder, f"{notebook}/paired.csv")
    if t is None:
        return None
    t = t[(t.weights == "imagenet") & (t.comparison == comparison) & (t.metric == PAIRED_METRIC)]
    if backbone is not None:
        t = t[t.backbone == backbone]
    return t.iloc[0] if len(t) else None


def paired_cell(r) -> str:
    """One paired.csv row as a cell: the difference (points) with its interval, the queries it rests on
    and :func:`paired_verdict`'s word in brackets."""
    return (f"{PAIRED_METRIC} {r.difference:+.2f} [{r.low:+.2f}, {r.high:+.2f}] points over {int(r.queries)} queries "
            f"({paired_verdict(r.low, r.high)})")


def _seeds_range(n, lo, hi) -> str:
    return f"[{_g(lo)}, {_g(hi)}] ({int(n)} seeds)"


def table1_accuracy(folder: Path):
    """Table 1: a spot of L = 60 frames (or the paper's L nearest to the folder's) is classified at the
    paper's accuracy. From ``01_spot_grouping/table1.csv`` (accuracy %, over seeds, random split): the
    median of the converged seeds (acc_median_converged_%) judged, every seed's mean, sd and range shown."""
    t = _csv(folder, "01_spot_grouping/table1.csv")
    if t is None:
        return None
    if t.paper_acc_pct.isna().all():
        return f"no L of the paper's (50, 60, 70) in this run (L = {', '.join(map(str, t.frames_per_spot))})", UNTESTABLE
    rows = t[t.frames_per_spot == 60]
    r = (rows if len(rows) else t.dropna(subset=["paper_acc_pct"])).iloc[0]
    conv = spot_cnn_convergence(folder, "01_spot_grouping", r.frames_per_spot)
    med = None if pd.isna(r.acc_median_converged_pct) else float(r.acc_median_converged_pct)
    head = f"median of the converged seeds {_g(med)}" if med is not None else "no converged seed"
    text = (f"L = {int(r.frames_per_spot)}: {head}; all seeds {_g(r.acc_mean_pct)} ± {_g(r.acc_std_pct)} "
            f"[{_g(r.acc_min_pct)}, {_g(r.acc_max_pct)}]; {conv.text()}")
    return text, value_verdict(r.paper_acc_pct, med, conv)


def table1_ranking(folder: Path):
    """Table 1: L = 60 ranks above L = 50 and 70 (seed ranges of ``01_spot_grouping/table1.csv``)."""
    t = _csv(folder, "01_spot_grouping/table1.csv")
    if t is None:
        return None
    arms = {int(r.frames_per_spot): (r.seeds, r.acc_min_pct, r.acc_max_pct) for r in t.itertuples()}
    if 60 not in arms or len(arms) < 2:
        return "L = 60 not run (too few frames per walk)", UNTESTABLE
    text = "; ".join(f"L = {k}: {_seeds_range(*v)}" for k, v in sorted(arms.items()))
    if budget_limited(t.converged_seeds.sum(), t.seeds.sum()):
        return text, BUDGET
    return text, rank_verdict(60, arms)


def learning_curves(folder: Path):
    """Figures 3-4: validation accuracy never below 96 % after epoch 45 (random split, every seed of
    ``02_training_over_seeds/per_seed.csv``: each seed's lowest after epoch 45, their median over the
    converged seeds judged)."""
    t = _csv(folder, "02_training_over_seeds/per_seed.csv")
    if t is None:
        return None
    t = t[t.split == "random"]
    cell, med = converged_median(t["min_val_acc_after_ep45_pct"], t.converged.astype(bool), " %")
    conv = spot_cnn_convergence(folder, "02_training_over_seeds")
    return f"each seed's lowest after epoch 45: {cell}; {conv.text()}", value_verdict(96, med, conv)


def confusion(folder: Path):
    """Figure 5 / Table 2: 10 of 452 test frames misclassified (2.21 %); per seed from
    ``03_confusion_matrix/errors_per_seed.csv`` (02's models), the share's median over 02's converged
    seeds judged."""
    t = _csv(folder, "03_confusion_matrix/errors_per_seed.csv")
    if t is None:
        return None
    t = t[t.split == "random"]
    share = 100 * t.misclassified / t.test_frames
    cell, med = converged_median(share, converged_flags(folder, t.seed), " %")
    conv = spot_cnn_convergence(folder, "02_training_over_seeds") or Convergence(0, len(t), "02 not run")
    text = (f"{between(t.misclassified.min(), t.misclassified.max())} of {int(t.test_frames.iloc[0])} "
            f"misclassified; share: {cell}; {conv.text()}")
    return text, value_verdict(100 * 10 / 452, med, conv, higher_is_better=False)


def shift(folder: Path):
    """Table 3: 92 % accuracy with every frame shifted one pixel right (``04_shift_robustness/table3.csv``,
    02's models): judged on the held-out frames (shift1_test_only_%; tables without it: every frame,
    said so), the median over 02's converged seeds, the unshifted held-out median beside it."""
    t = _csv(folder, "04_shift_robustness/table3.csv")
    if t is None:
        return None
    held = "shift1_test_only_pct" in t
    flags = converged_flags(folder, t.seed)
    cell, med = converged_median(t["shift1_test_only_pct" if held else "shift1_all_frames_pct"], flags, " %")
    before = converged_median(t["original_test_pct"], flags)[1] if flags.any() else t["original_test_pct"].median()
    conv = spot_cnn_convergence(folder, "02_training_over_seeds") or Convergence(0, len(t), "02 not run")
    text = (f"{'held-out' if held else 'all (training included)'} frames shifted: {cell}"
            f" (unshifted {_g(before)} %); {conv.text()}")
    return text, value_verdict(92, med, conv)


def dictionary(folder: Path):
    """The dictionary at tau = L + Delta as a loop-closure detector: closure precision at least
    :data:`DICTIONARY_PRECISION` % (what the field asks of a loop-closure detector; the paper reports
    no precision). Read from notebook 05's seeds (:func:`dictionary_over_seeds`) where the folder has
    them; else on the leaderboard's evaluation queries (``13_leaderboard/leaderboard.csv``, its
    "main paper" rows, one per CNN seed: their median judged). Its CNN is trained as 02's seeds (the
    same L and epochs, by the manifests): their convergence is its (:data:`CONVERGED`); where 13 and
    02 ran with other L or epochs, its convergence is not known and the row is not resolved."""
    if (folder / summary.DICTIONARY_SEEDS).is_file():
        return dictionary_over_seeds(folder)
    t = _csv(folder, "13_leaderboard/leaderboard.csv")
    if t is None:
        return None
    rows = t[t.method.str.startswith("main paper")]
    if not len(rows):
        return None
    r = rows.iloc[0]
    declared, false = int(r.closures_declared), int(r.closures_false)
    rates = [summary.closure_rates(x.to_dict()) for _, x in rows.iterrows()]
    precisions = [p for p, _ in rates if p is not None]
    seeds = f"{len(rows)} CNN seed{'s' * (len(rows) != 1)}" + (", no spread" if len(rows) == 1 else "")
    text = (f"tau = {_g(r.threshold)}: {declared - false} of {declared} closures right "
            f"(precision {_g(precisions[0]) if precisions else 'n/a'} %), recall {_g(rates[0][1])} % of "
            f"{int(r.revisit_queries)} revisit queries; {seeds}")
    keys = ("frames_per_spot", "epochs")
    family = spot_cnn_convergence(folder, "02_training_over_seeds")
    if family is None or [_parameters(folder, "13_leaderboard").get(k) for k in keys] != \
            [_parameters(folder, "02_training_over_seeds").get(k) for k in keys]:
        return text + "; its CNN's convergence not recorded", f"{UNRESOLVED} (convergence of its CNN not recorded)"
    conv = Convergence(0 if budget_limited(family.converged, family.seeds) else len(rows), len(rows), "")
    text += f"; trained as 02's seeds: {family.text()}"
    median = float(pd.Series(precisions).median()) if precisions else None
    return text, value_verdict(DICTIONARY_PRECISION, median, conv)


def _derived_tau(folder: Path):
    """The tau notebook 05 derived (its summary.json's derived.tau, frames), or None."""
    path = folder / "05_dictionary_threshold" / "summary.json"
    return json.loads(path.read_text()).get("derived", {}).get("tau") if path.is_file() else None


def dictionary_over_seeds(folder: Path):
    """The dictionary's row from notebook 05's seeds (``seeds_summary.csv``, the paper's variant: its
    closure precision = true / flagged frames at tau, %, over each seed's CNN): the median over the
    converged seeds (``<stat>_median_converged``) judged against :data:`DICTIONARY_PRECISION`, every
    seed's [min, max] in the cell, the seeds counted converged by 05's own table (the spot CNN's rule,
    :data:`CONVERGED`); epochs taken from ``seeds.csv`` where present. A run where converged seeds
    flag no frame declares no closure: does not hold."""
    row = summary.dictionary_seeds_row(folder)
    r = pd.to_numeric(pd.Series({k.replace("%", "pct"): v for k, v in row.items() if k != "variant"}), errors="coerce")
    per_seed = _csv(folder, "05_dictionary_threshold/seeds.csv")
    taken = None if per_seed is None else per_seed[per_seed.variant == summary.DICTIONARY_VARIANT].epochs
    training = training_text(folder, "05_dictionary_threshold",
                             *((taken.min(), taken.max()) if taken is not None and len(taken) else ()))
    conv = Convergence(int(r.converged_seeds), int(r.seeds), training)
    tau = _derived_tau(folder)
    med = None if pd.isna(r.precision_median_converged_pct) else float(r.precision_median_converged_pct)
    spread = (f"all seeds [{_g(r.precision_min_pct)}, {_g(r.precision_max_pct)}] %"
              if pd.notna(r.precision_max_pct) else "no seed flagged a frame")
    head = (f"median of the converged seeds {_g(med)} %" if med is not None else
            "no converged seed flagged a frame" if conv.converged else "no converged seed")
    recall = (f"; recall median {_g(r.recall_median_pct)} % [{_g(r.recall_min_pct)}, {_g(r.recall_max_pct)}]"
              if pd.notna(r.recall_median_pct) else "")
    text = (f"{'tau = ' + _g(tau) + ': ' if tau is not None else ''}closure precision (true / flagged frames): "
            f"{head}, {spread}{recall}; {conv.text()}")
    if med is None and not budget_limited(conv.converged, conv.seeds):
        return text, FAILS
    return text, value_verdict(DICTIONARY_PRECISION, med, conv)


def speed(folder: Path):
    """The paper's 920 frames/s (``06_speed/paper_vs_run.csv``: the 70-frame window pipeline, frames/s,
    with the per-frame milliseconds' p95 beside it)."""
    t = _csv(folder, "06_speed/paper_vs_run.csv")
    if t is None:
        return None
    q = t.set_index("quantity")["this run"]
    fps = float(q["frames per second"])
    ms = str(q["ms per frame"]).replace(" (p95 ", " ms per frame, p95 ").rstrip(")")
    return f"{_g(fps)} frames/s ({ms} ms)", HOLDS if fps >= 920 else FAILS


def qi_ranking(folder: Path):
    """Qi 2024 Table 2: GhostNet's features rank first of the CNNs (``07_feature_baselines/table2.csv``)."""
    t = _csv(folder, "07_feature_baselines/table2.csv")
    if t is None:
        return None
    g = t[t.backbone == "ghostnet"]
    if not len(g):
        return "GhostNet not run here (07's backbones)", UNTESTABLE
    if (g.weights == "random init").all():
        return "GhostNet, VGG19, EfficientNet-B0, ShuffleNet v2 random-init here", UNTESTABLE
    return f"GhostNet AP {_g(g.AP_pct.max())} %", UNRESOLVED + " (one AP per network, no spread)"


def qi_depth(folder: Path):
    """Qi 2024 Tables 3-4: depth adds to RGB; read on the one network here with ImageNet weights,
    EfficientNet-Lite0 (``09_rgbd_features/rgbd.csv``, AP %)."""
    t = _csv(folder, "09_rgbd_features/rgbd.csv")
    if t is None:
        return None
    r = t[(t.backbone == "efficientnetlite0") & (t.weights == "imagenet")]
    if not len(r):
        return "no EfficientNet-Lite0 (ImageNet) row in 09 (its backbones)", UNTESTABLE
    if "AP_RGB-D_pct" not in r or pd.isna(r.iloc[0]["AP_RGB-D_pct"]):
        return "no depth", UNTESTABLE
    r = r.iloc[0]
    text = f"EfficientNet-Lite0 (ImageNet) AP {_g(r.AP_RGB_pct)} -> {_g(r['AP_RGB-D_pct'])} %"
    pair = paired_row(folder, "09_rgbd_features", "RGB-D minus RGB", "efficientnetlite0")
    if pair is None:
        return text, UNRESOLVED + " (one AP each, no spread)"
    return f"{text}; paired, RGB-D minus RGB: {paired_cell(pair)}", paired_verdict(pair.low, pair.high)


def qi_lsh(folder: Path):
    """Qi 2024 Table 6: multi-probe QDP-RHLSH matches faster than brute force at about its AP, on the
    ImageNet descriptor of ``11_lsh_matching/table6.csv`` (ms per query, mean ± sd over hyperplane seeds)."""
    t = _csv(folder, "11_lsh_matching/table6.csv")
    if t is None:
        return None
    t = t[t.weights.str.contains("imagenet")]
    if not len(t):
        return None
    t = t[t.label == t.label.iloc[0]]                    # one descriptor: the first with ImageNet weights
    b = t[t.variant == "brute force"].iloc[0]
    q = t[t.variant == "QDP-RHLSH"].iloc[0]
    text = (f"{b.label}: brute force {b.ms_per_query:.2g} ms, QDP {q.ms_per_query:.2g} ± {q.ms_sd:.1g} ms "
            f"per query; pair AP {_g(b.AP_pairs_pct)} -> {_g(q.AP_pairs_pct)} %")
    if q.ms_per_query + q.ms_sd < b.ms_per_query - b.ms_sd:
        return text, HOLDS if q.AP_pairs_pct >= b.AP_pairs_pct - 1 else FAILS
    return text, FAILS if q.ms_per_query - q.ms_sd > b.ms_per_query + b.ms_sd else UNRESOLVED


def _postprocessing(folder: Path):
    """08's rows for the one network there with ImageNet weights (AP % on the evaluation part), or None."""
    t = _csv(folder, "08_descriptor_postprocessing/postprocessing.csv")
    if t is None:
        return None
    t = t[t.weights.str.contains("imagenet")]
    return t if len(t) else None


NO_SPLIT = ("no honest tuning/evaluation split (untuned rows only)", UNTESTABLE)   # 08 run where every revisit is close


def _ap(t: pd.DataFrame, variant: str, median: str) -> float:
    return float(t[(t.variant == variant) & (t.median_filter == median)].AP_eval_pct.iloc[0])


def zhang_whitening(folder: Path):
    """Zhang 2017: PCA-whitened CNN features beat raw ones (08, raw vs whitened at the paper's dimension
    and at the dimension picked on the tuning part, no median filter)."""
    t = _postprocessing(folder)
    if t is None or "AP_eval_pct" not in t:
        return None if t is None else NO_SPLIT
    raw, paper = _ap(t, "raw", "none"), _ap(t, "PCA-whitened, paper dim", "none")
    tuned = _ap(t, "PCA-whitened, tuned dim", "none")
    text = f"{t.label.iloc[0]}: AP raw {_g(raw)}, whitened {_g(paper)} (paper's dim), {_g(tuned)} (tuned dim)"
    pairs = {dim: paired_row(folder, "08_descriptor_postprocessing", f"PCA-whitened, {dim} dim minus raw")
             for dim in ("paper", "tuned")}
    pairs = {k: v for k, v in pairs.items() if v is not None}
    if not pairs:
        return text, UNRESOLVED + " (one split, no spread)"
    words = {k: paired_verdict(v.low, v.high) for k, v in pairs.items()}
    text += "; paired, whitened minus raw: " + ", ".join(f"{k}'s dim {paired_cell(v)}" for k, v in pairs.items())
    agreed = set(words.values())
    return text, agreed.pop() if len(agreed) == 1 else f"{UNRESOLVED} (the two dimensions disagree)"


def zca_median(folder: Path):
    """ResNet/Inception/ZCA: a median filter on the ZCA-whitened similarity matrix improves it (08)."""
    t = _postprocessing(folder)
    if t is None or "AP_eval_pct" not in t:
        return None if t is None else NO_SPLIT
    before, after = _ap(t, "ZCA, tuned dim", "none"), _ap(t, "ZCA, tuned dim", "median (tuned)")
    text = f"{t.label.iloc[0]}: AP {_g(before)} -> {_g(after)}"
    pair = paired_row(folder, "08_descriptor_postprocessing", "ZCA + median filter (tuned) minus ZCA")
    if pair is None:
        return text, UNRESOLVED + " (one split, no spread)"
    return f"{text}; paired, filtered minus unfiltered: {paired_cell(pair)}", paired_verdict(pair.low, pair.high)


def _arms(t: pd.DataFrame, key: str) -> dict[str, tuple[int, float, float]]:
    return {getattr(r, key): (r.seeds, r.AP_min, r.AP_max) for r in t.itertuples()}


def xu_networks(folder: Path, table: str, descriptors) -> tuple[int, int, str] | None:
    """(converged, networks, epochs) of notebook 10's networks behind ``descriptors`` (rows of
    ``10_siamese_rgbd/<table>_per_seed.csv``, one per network and seed): how many converged by its
    ``converged`` column (``siamese.converged``, :data:`CONVERGED`), how many there are, and the
    epochs taken in words ("a-b epochs taken (cap C)"). None for a table written before it recorded
    each network's epoch_cap (its epochs were a fixed budget)."""
    t = _csv(folder, f"10_siamese_rgbd/{table}_per_seed.csv")
    if t is None or "epoch_cap" not in t:
        return None
    t = t[t.descriptor.isin(list(descriptors))]
    if not len(t):
        return None
    caps = "/".join(str(int(c)) for c in sorted(t.epoch_cap.unique()))
    return (int(t.converged.eq(True).sum()), len(t),
            f"{between(t.epochs.min(), t.epochs.max())} epochs taken (cap {caps})")


def _xu_order(t: pd.DataFrame, key: str, claimed: str, nets: tuple[int, int, str] | None = None):
    """(text, verdict) of "``claimed`` ranks first" among the arms of notebook 10's summary rows ``t``
    (AP % over seeds): budget-limited where fewer than half of the arms' networks converged, else
    ``rank_verdict``. The networks are counted by ``nets`` (:func:`xu_networks`, the per-seed
    converged column, the epochs taken said) where given, else by the summary's converged_seeds
    (tables written before it was kept read as converged)."""
    arms = _arms(t, key)
    text = "; ".join(f"{k} {_seeds_range(*v)}" for k, v in arms.items())
    if nets is not None:
        k, n, epochs = nets
        text += f"; {k} of {n} networks converged, {epochs}"
        return text, BUDGET if budget_limited(k, n) else rank_verdict(claimed, arms)
    if "converged_seeds" in t and budget_limited(t.converged_seeds.sum(), t.seeds.sum()):
        return text + f", {int(t.converged_seeds.sum())} of {int(t.seeds.sum())} networks converged", BUDGET
    return text, rank_verdict(claimed, arms)


def xu_supervision(folder: Path):
    """Xu 2022: multi-task supervision ranks above softmax and contrastive (10, held-out AP % over seeds)."""
    t = _csv(folder, "10_siamese_rgbd/supervisions.csv")
    if t is None:
        return None
    t = t[t.supervision.isin(["softmax", "contrastive", "multitask"])]
    return _xu_order(t, "supervision", "multitask", xu_networks(folder, "supervisions", t.descriptor))


def _fusion_rows(folder: Path, fusions) -> pd.DataFrame | None:
    """10's fusions.csv rows whose fusion is in ``fusions`` (mid-level at the paper's layer, conv2,
    for "mid"); None without the table; an empty frame without depth."""
    t = _csv(folder, "10_siamese_rgbd/fusions.csv")
    if t is None or "fusion" not in t:
        return t if t is None else t.iloc[:0]
    return t[t.fusion.isin([f for f in fusions if f != "mid"]) | ((t.fusion == "mid") & (t.layer == "conv2")
                                                                  & ("mid" in fusions))]


def xu_fusion(folder: Path):
    """Xu 2022: late fusion ranks above early and mid-level fusion at the paper's layer (conv2) (10)."""
    t = _fusion_rows(folder, ("early", "mid", "late"))
    if t is None:
        return None
    if not len(t):
        return "no depth", UNTESTABLE
    return _xu_order(t, "fusion", "late", xu_networks(folder, "fusions", t.descriptor))


def xu_depth(folder: Path):
    """Xu 2022: depth helps: late fusion above the same network on RGB only (10)."""
    t = _fusion_rows(folder, ("RGB only", "late"))
    if t is None:
        return None
    if not len(t) or (t.fusion == "late").sum() == 0:
        return "no depth", UNTESTABLE
    return _xu_order(t, "fusion", "late", xu_networks(folder, "fusions", t.descriptor))


MAIN, QI, ZCA, ZHANG, XU = ("main paper", "Qi 2024", "ResNet/Inception/ZCA", "Zhang 2017", "Xu 2022")


class Claim(NamedTuple):
    """One headline claim. paper, item: where the paper makes it; claim: what it says; value: the
    paper's number; reader: results folder -> (measured, verdict) or None (its table is missing);
    notebook: the notebook that concludes on it; covers: the items of ``study.coverage.ITEMS`` (of
    the same paper) whose "claim holds" cell it fills."""
    paper: str
    item: str
    claim: str
    value: str
    reader: Callable
    notebook: str
    covers: tuple[str, ...]


CLAIMS = [
    Claim(MAIN, "Table 1", "spots of L frames are classified at the paper's accuracy", "97 / 98 / 97 % (L = 50 / 60 / 70)",
          table1_accuracy, "01_spot_grouping", ("Table 1",)),
    Claim(MAIN, "Table 1", "L = 60 is the best grouping", "60 > 50, 70", table1_ranking, "01_spot_grouping",
          ("Table 1",)),
    Claim(MAIN, "Fig. 3-4", "validation accuracy stays >= 96 % after epoch 45", ">= 96 %", learning_curves,
          "02_training_over_seeds", ("Fig. 3, Fig. 4",)),
    Claim(MAIN, "Fig. 5, Table 2", "few test frames misclassified", "10 of 452 (2.21 %)", confusion,
          "03_confusion_matrix", ("Fig. 5", "Table 2")),
    Claim(MAIN, "Table 3", "a 1-pixel shift keeps the accuracy", "92 %", shift, "04_shift_robustness",
          ("Table 3",)),
    Claim(MAIN, "dictionary", "tau = L + Delta declares loop closures", "loop closures detected (no precision given)",
          dictionary, "13_leaderboard", ("Sec. dictionary",)),
    Claim(MAIN, "speed", "920 frames/s", "920 frames/s (i7-8750H)", speed, "06_speed", ("speed claim",)),
    Claim(QI, "Table 2", "GhostNet's features rank first", "GhostNet AP 53.1 % (TUM)", qi_ranking,
          "07_feature_baselines", ("Table 2",)),
    Claim(QI, "Tables 3-4", "depth adds to RGB", "53.1 -> 59.4 % (GhostNet, TUM)", qi_depth, "09_rgbd_features",
          ("Tables 3, 4",)),
    Claim(QI, "Table 6", "QDP-RHLSH is faster than brute force at its AP", "faster, AP kept", qi_lsh,
          "11_lsh_matching", ("Table 6",)),
    Claim(ZHANG, "Fig. 4-5", "PCA-whitened CNN features beat raw ones", "qualitative (PR curves)", zhang_whitening,
          "08_descriptor_postprocessing", ("Fig. 4", "Fig. 5")),
    Claim(ZCA, "Table III", "a median filter on the ZCA similarity helps", "qualitative", zca_median,
          "08_descriptor_postprocessing", ("Table III",)),
    Claim(XU, "Fig. 8", "multi-task supervision ranks first", "multi-task > softmax, contrastive", xu_supervision,
          "10_siamese_rgbd", ("Fig. 8",)),
    Claim(XU, "Fig. 9", "late fusion ranks first", "late > early, mid (conv2)", xu_fusion, "10_siamese_rgbd",
          ("Fig. 9",)),
    Claim(XU, "Fig. 9", "depth helps (late fusion above RGB only)", "RGB-D > RGB", xu_depth, "10_siamese_rgbd",
          ("Fig. 9",)),
]


def dataset_name(folder: Path) -> str:
    """The dataset a results folder ran on, by its notebooks' manifests, as the table names it."""
    name = provenance.dataset_name(folder) or Path(folder).name
    return DATASETS.get(name, name)


def verdicts(results_dirs) -> pd.DataFrame:
    """One row per claim of :data:`CLAIMS`: paper, item, claim, paper value, then one "measured: verdict"
    cell per results folder, named by its dataset."""
    folders = [Path(d) for d in results_dirs]
    rows = []
    for c in CLAIMS:
        row = {"paper": c.paper, "item": c.item, "claim": c.claim, "paper value": c.value}
        for f in folders:
            got = c.reader(f)
            row[dataset_name(f)] = NOT_RUN if got is None else f"{got[0]}: **{got[1]}**"
        rows.append(row)
    return pd.DataFrame(rows)


def conclusion(results_dir, notebook: str) -> str:
    """The verdicts of the claims ``notebook`` (a stem such as "01_spot_grouping") concludes on, for the
    dataset of ``results_dir``, as Markdown bullets ("" when the notebook has none): what a notebook's last
    cell shows, read from the tables it has just written."""
    folder, lines = Path(results_dir), []
    for c in CLAIMS:
        if c.notebook != notebook:
            continue
        got = c.reader(folder)
        measured, word = (NOT_RUN, NOT_RUN) if got is None else got
        lines.append(f"* {c.paper}, {c.item}: *{c.claim}* (paper: {c.value}). On {dataset_name(folder)}: {measured}: "
                     f"**{word}**.")
    return "\n".join(lines)


def claim_holds(paper: str, item: str, results_dirs) -> str:
    """The "claim holds" cell of a coverage row (``study.coverage``: its paper's full name and item):
    "<claim>: <dataset> <verdict>, ..." for each claim covering it, "" where none does."""
    folders = [Path(d) for d in results_dirs]
    cells = []
    for c in CLAIMS:
        if paper.startswith(c.paper) and item in c.covers:
            found = [(dataset_name(f), c.reader(f)) for f in folders]
            cells.append(f"{c.claim}: " + ", ".join(f"{n} {got[1]}" for n, got in found if got is not None))
    return "; ".join(cells)


def markdown(results_dirs) -> str:
    """:func:`verdicts` as a markdown table (cells unpadded: the README's source stays readable) with
    the rules under it."""
    t = verdicts(results_dirs)
    return summary.table(list(t.columns), t.itertuples(index=False)) + "\n" + RULES + "\n"


def write(results_dirs, out="results/verdict.md", readme=None) -> Path:
    """Write :func:`verdicts` to ``out`` (.md) and beside it (.csv), and refill the ``verdict`` block
    of the Markdown file ``readme`` (when given)."""
    out, text = Path(out), markdown(results_dirs)
    write_atomic(out.with_suffix(".csv"), verdicts(results_dirs).replace(r"\*\*", "", regex=True).to_csv(index=False))
    write_atomic(out, "# Does each paper's claim hold here?\n\nWritten by `make readme` (`python -m greenloop verdict`) "
                 "from the tables of " + ", ".join(f"`{d}`" for d in results_dirs) + ".\n\n" + text)
    if readme:
        fill_block(readme, "verdict", text)
    return out
