"""SeqSLAM (``greenloop.methods.seqslam.seqslam``) as a registered detector: OpenSeqSLAM's published parameters,
and the same method tuned on greenloop-seq's grid (seq_len L = ds + 1, R_window) as a second row.

Knob records: descriptor "seqslam", whitening "none", seq_len (ds + 1), contrast_window
(R_window). params read: seq_lens, contrast_windows.
"""
from __future__ import annotations

import numpy as np

from greenloop.methods.greenloop_seq import seqmatch
from greenloop.methods.interface import Data, Entry
from greenloop.methods.seqslam import seqslam as slam, seqslam_stream

PUBLISHED, TUNED = "SeqSLAM (published)", "SeqSLAM (tuned)"
SEQSLAM_PUBLISHED = {"descriptor": "seqslam", "whitening": "none", "seq_len": slam.DS + 1,
                     "contrast_window": slam.R_WINDOW}


def describe(data: Data) -> tuple[dict, dict]:
    """The SeqSLAM descriptors (M, 2048) of the described frames (``seqslam.describe``)."""
    return ({} if "seqslam" in data.descriptors else {"seqslam": slam.describe(data.dataset, step=data.frame_step)}), {}


def _similarity(data: Data) -> np.ndarray:
    """``seqslam.similarity_matrix`` of the run's SeqSLAM descriptors, computed once per Data
    (``data.cache["seqslam_similarity"]``): every row of the grid and both rows reuse it."""
    if "seqslam_similarity" not in data.cache:
        data.cache["seqslam_similarity"] = slam.similarity_matrix(data.descriptors["seqslam"])
    return data.cache["seqslam_similarity"]


def tune(data: Data) -> tuple[list, dict, dict]:
    """The tuned row (grid seq_lens x contrast_windows, per-query AUC-PR on the tuning queries),
    then the published one; only the published one without a tuning part."""
    if data.tune is None:
        return [], {PUBLISHED: dict(SEQSLAM_PUBLISHED)}, {}
    p = data.params
    rows = seqslam_stream.tune_knobs(data.descriptors["seqslam"], data.GT, data.exclude, data.tune, p["seq_lens"],
                           p["contrast_windows"], _similarity(data))
    knobs, best = seqmatch.pick_knobs(rows, {TUNED: (["seqslam"], list(p["seq_lens"]))})
    knobs[PUBLISHED] = dict(SEQSLAM_PUBLISHED)
    return rows, knobs, best


def score(k: dict, data: Data) -> np.ndarray:
    """(M, M) float32 ``seqslam_stream.score_matrix`` of a knob record."""
    return seqslam_stream.score_matrix(data.descriptors["seqslam"], data.exclude, k["seq_len"] - 1, k["contrast_window"],
                                       S0=_similarity(data))


def stream(k: dict, threshold, data: Data) -> seqslam_stream.Detector:
    """The streaming ``seqslam_stream.Detector`` of a knob record (threshold None or NaN: scores only)."""
    t = None if threshold is None or not np.isfinite(threshold) else float(threshold)
    return seqslam_stream.Detector(t, data.exclude, k["seq_len"] - 1, k["contrast_window"])


def describer(k: dict, data: Data):
    """One decoded BGR frame -> its SeqSLAM descriptor (2048,)."""
    return lambda f: slam.describe_frames([f])[0]


def knob_text(k: dict) -> str:
    """One line of a SeqSLAM knob record for the table."""
    return f"64x32 patch-normalised, SAD, ds {k['seq_len'] - 1}, R_window {k['contrast_window']}, v 0.8..1.2"


ENTRY = Entry("seqslam", describe, tune, score, stream, describer, knob_text, checked=True,
              cli_knobs=dict(SEQSLAM_PUBLISHED))
