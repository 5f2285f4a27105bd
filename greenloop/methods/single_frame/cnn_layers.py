"""Single-frame matchers on CNN layer descriptors: per network, the depth and pooling chosen on the
tuning queries (greenloop.features.layers; notebook 07's layer study).

Each network of ``params["layer_backbones"]`` gives one row, "<network>, best layer (single
frame)": its descriptor is one of the network's nine layer descriptors (early / mid / last map x
avg / grid2 / gem pooling), picked with the whitening and contrast window of every single-frame
CNN row by the one tuning budget (per-query AUC-PR on the tuning queries). Without a tuning part a
row takes the last map, globally averaged (the descriptor of the "single-frame" rows), untuned.
Matching, streaming and timing are greenloop-seq's at seq_len 1, as for every single-frame row.
"""
from __future__ import annotations

from greenloop import features
from greenloop.features import layers
from greenloop.methods.greenloop_seq import entry as greenloop_seq
from greenloop.methods.interface import Data, Entry
from greenloop.methods.single_frame import entry as single_frame


def row_name(network: str) -> str:
    """The leaderboard row of a network's layer-chosen matcher."""
    return f"{network}, best layer (single frame)"


def groups(params: dict) -> dict:
    """{row: the network's layer descriptors, last-avg first (the untuned choice)}."""
    out = {}
    for net in params.get("layer_backbones", ()):
        first = layers.specs([net], ["last"], ["avg"])[0]
        out[row_name(net)] = [first] + [s for s in layers.specs([net]) if s != first]
    return out


def describe(data: Data) -> tuple[dict, dict]:
    """Every layer descriptor of each network (``features.extract_all``: one cached pass per network)."""
    specs = [s for g in groups(data.params).values() for s in g]
    if not specs:
        return {}, {}
    return features.extract_all(data.dataset, specs, data.params.get("weights", "auto"), step=data.frame_step)


def tune(data: Data) -> tuple[list, dict, dict]:
    """Each network's row: layer, pooling, whitening and contrast window picked on the tuning queries."""
    g = groups(data.params)
    specs = [s for v in g.values() for s in v]
    if not specs:
        return [], {}, {}
    return single_frame.tune_names(data, specs, specs, groups=g)


ENTRY = Entry("cnn-layers", describe, tune, greenloop_seq.score, greenloop_seq.stream, greenloop_seq.describer,
              greenloop_seq.knob_text)
