"""Single-frame matchers: the cosine of one frame's L2-normalised descriptor to every stored frame.

Each is greenloop-seq's search at seq_len 1 (a ``seqstream.Detector``; ``greenloop_seq``'s score,
stream and knob text). Knobs (one tuning budget): the local contrast normalisation window
(``contrast_windows``) and, for the CNNs, PCA whitening fitted on the tuning frames (L2 -> whiten
-> L2) at each of ``whiten_dims`` or none. Without a tuning part: no contrast normalisation, no
whitening. Rows are named "<descriptor> (single frame)".

Notebook 08's median filter is not a knob here: its window is centred on the query (square: the
block of queries j - s//2 .. j + s//2; diagonal: S[i + t, j + t], |t| <= s//2), so it reads future
frames; its causal (look-back) form along the diagonal is a trajectory mean, i.e. greenloop-seq
with seq_len = the window, which is the sequence row, not a single-frame one.

:data:`ENTRY` ("single-frame") describes the study's descriptors (params: cnn_backbones,
random_control, weights, input_size, vocab_size, whiten_dims, contrast_windows, velocities) and every
features registry line marked ``leaderboard=True``: a new descriptor reaches the leaderboard, and
``detect --method single-frame --descriptor NAME`` (:func:`cli_knobs`), through the features registry
alone (docs/ARCHITECTURE.md, "Adding a descriptor").
"""
from __future__ import annotations

import numpy as np

from greenloop import features
from greenloop.methods.greenloop_seq import entry as greenloop_seq, seqmatch, seqstream
from greenloop.methods.interface import Data, Entry


def row_name(descriptor: str) -> str:
    """The leaderboard row of a descriptor's single-frame matcher."""
    return f"{descriptor} (single frame)"


def specs(params: dict) -> list:
    """The study's single-frame descriptors: the CNNs, the random-init control, SIFT-BoVW, pixels,
    then every features registry line marked ``leaderboard=True`` (in registry order)."""
    study = list(params["cnn_backbones"]) + [params["random_control"], "sift_bovw", "pixels"]
    return study + [n for n, b in features.BACKBONES.items() if b.leaderboard and n not in study]


def projections(feats: dict, names, fit, dims) -> dict:
    """Whitening candidates of each CNN descriptor: {name: {"none": None, "pca k": Projection}}.
    feats: {name: (N, D)}; names: the entries that get whitening; fit: (N,) bool frames to fit
    on (the tuning part; None: every frame, no labels used); dims: requested dimensions (clipped
    to the rank, the label says the kept one); a descriptor whose fitting frames are all alike
    gets "none" only."""
    out = {}
    for s in names:
        X = feats[s] if fit is None else feats[s][np.asarray(fit, dtype=bool)]
        cands = {"none": None}
        for k in dims:
            try:
                p = seqmatch.fit_projection(X, int(k))
            except ValueError:            # every fitting frame alike (e.g. a GeM of all-negative maps)
                break
            cands.setdefault(f"pca {p.output_dim}", p)
        out[s] = cands
    return out


def untuned(names) -> dict:
    """Knob records without a tuning part: no contrast normalisation, no whitening."""
    return {row_name(s): {"descriptor": s, "whitening": "none", "seq_len": 1, "contrast_window": 0} for s in names}


def tune_names(data: Data, names, whitened=(), groups=None) -> tuple[list, dict, dict]:
    """Tune the single-frame matchers of the given descriptors (``whitened``: those offered PCA
    whitening, fitted on the tuning frames and kept in ``data.cache["projections"]``). groups:
    {row name: [descriptors]} for rows that choose their descriptor too (default one row per
    descriptor, :func:`row_name`); without a tuning part each row takes its list's first."""
    groups = groups or {row_name(s): [s] for s in names}
    if data.tune is None:
        return [], {r: untuned(g[:1])[row_name(g[0])] for r, g in groups.items()}, {}
    p = data.params
    proj = data.cache.setdefault("projections", {})
    proj.update(projections(data.descriptors, list(whitened), data.tune, p.get("whiten_dims", ())))
    rows = seqstream.tune_knobs({s: data.descriptors[s] for s in names}, data.GT, data.exclude, data.tune, [1],
                               p["contrast_windows"], p["velocities"], {s: proj[s] for s in whitened})
    knobs, best = seqmatch.pick_knobs(rows, {r: (g, [1]) for r, g in groups.items()})
    return rows, knobs, best


def describe(data: Data) -> tuple[dict, dict]:
    """The study's single-frame descriptors (``features.extract_all``, the descriptor cache)."""
    p = data.params
    return features.extract_all(data.dataset, specs(p), p.get("weights", "auto"), p.get("input_size"),
                                step=data.frame_step, vocab_size=p.get("vocab_size", features.DEFAULT_VOCAB_SIZE))


def tune(data: Data) -> tuple[list, dict, dict]:
    """Every study descriptor's matcher; the CNNs (and the random control) offered whitening."""
    p = data.params
    return tune_names(data, specs(p), list(p["cnn_backbones"]) + [p["random_control"]])


def cli_knobs(descriptor: str = "pixels") -> dict:
    """The untuned knob record of one descriptor's single-frame matcher: what ``detect --method
    single-frame --descriptor NAME`` streams (``ENTRY.stream`` / ``ENTRY.describer`` of it).
    ValueError, listing the registry's names, for a name ``features.parse`` cannot read."""
    features.parse(descriptor)
    return untuned([descriptor])[row_name(descriptor)]


ENTRY = Entry("single-frame", describe, tune, greenloop_seq.score, greenloop_seq.stream, greenloop_seq.describer,
              greenloop_seq.knob_text, cli_knobs=cli_knobs("pixels"))

