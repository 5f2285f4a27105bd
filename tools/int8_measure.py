"""The CNN configuration (greenloop-seq-cnn) float against its int8 CNN part
(features.FUSED_INT8) and its int8 rows (store_dtype "int8"), each alone and both: R@1 (%) on a
dataset's target streams (sequence.yaml's protocol, built and scored as the leaderboard's target
protocols: experiments.leaderboard.prepare / _protocol / tune and leaderboard.rows.metric_rows), and
on Nordland the benchmark's timing (speed.timing.time_methods over the leaderboard's timing window,
3 repeats): whole decision, describe only and match only, in frames/s and ms.

    PYTHONPATH=. .venv/bin/python tools/int8_measure.py data/nordland|data/gardenspoint [all|VARIANT,...] [r1|time]

Numbers printed, not written: results/ holds the committed tables only.
"""
import json, sys, time
import numpy as np
from greenloop import features
from greenloop.datasets import sequence
from greenloop.experiments import leaderboard as L
from greenloop.experiments.leaderboard import rows as lb
from greenloop.methods.greenloop_seq import entry as ge, seqmatch
from greenloop.methods.interface import Entry
from greenloop.speed import timing

CNN = ge.named_default(seqmatch.CNN_NAME)
VARIANTS = {"float": {}, "int8 CNN": dict(descriptor=features.FUSED_INT8), "int8 rows": dict(store_dtype="int8"),
            "int8 CNN + int8 rows": dict(descriptor=features.FUSED_INT8, store_dtype="int8")}
which = sys.argv[2].split(",") if len(sys.argv) > 2 and sys.argv[2] != "all" else list(VARIANTS)
MODE = sys.argv[3] if len(sys.argv) > 3 else "r1"

def make_entry(name, k):
    """A registry Entry streaming knob record k untuned at its fixed threshold, under ``name``."""
    def describe(data):
        """The record's descriptor where ``data`` lacks it."""
        d = k["descriptor"]
        if d in data.descriptors:
            return {}, {}
        X, info = seqmatch.describe(data.dataset, d, step=data.frame_step, return_info=True)
        return {d: X}, {d: info}
    return Entry(name, describe, lambda data: ([], {name: k}, {}), ge.score, ge.stream, ge.describer, ge.knob_text,
                 checked=True, cli_knobs=k)

REG = {n: make_entry(n, dict(CNN, **v)) for n, v in VARIANTS.items() if n in which}
PARAMS = dict(seq_lens=[5, 10, 20], velocities=[0.8, 1.0, 1.25], fps_frames=300, timing_repeats=3, threshold_rule="f1",
              weights="auto", input_size=128)

def run(dataset, ref):
    """R@1 per target stream and mode (or, MODE "time", the timing) of every variant on ``dataset``
    (reference: the first ``ref`` frames). Returns {"stream | mode | variant": R@1 %}."""
    t0 = time.perf_counter()
    data, split = L.prepare(dataset, 1, 0.5, 150, 0.5, ref, PARAMS)
    full = L._every_frame(data, REG)
    print("described", dataset, round(time.perf_counter() - t0, 1), "s", flush=True)
    out = {}
    for s in sequence.open(dataset).protocol.streams:
        d, sp = L._protocol(full, s, 0.5)
        if MODE == "time":
            time_stream(d, {n: e.cli_knobs for n, e in REG.items()})
            continue
        tuned = L.tune(d, REG)
        for m, S in tuned.S.items():
            for r in lb.metric_rows(S, d.GT, d.exclude, d.evalq, sp.reference):
                out[f"{s.name} | {r['mode']} | {m}"] = round(r["R@1_%"], 2)
        print(json.dumps(out, indent=1), flush=True)

    return out

def time_stream(d, knobs):
    """Print each variant's frames/s (whole decision), describe ms and match ms on stream ``d``."""
    fixed = {m: k["fixed_threshold"] for m, k in knobs.items()}
    dets = {m: REG[m].stream(k, fixed[m], d) for m, k in knobs.items()}
    desc = {m: REG[m].describer(k, d) for m, k in knobs.items()}
    start, stop = lb.timing_window(d.evalq, PARAMS["fps_frames"])
    raw, _ = lb.decode_window(sequence.list_frames(d.dataset), d.frames, start, stop)
    methods, preload = lb.timing_methods(knobs, dets, desc, d.descriptors, start)
    print("window", start, stop, "stored at start", start, flush=True)
    whole = timing.time_methods(methods, raw, preload, 3)
    dm = [timing.Method(m, lambda X: None, (lambda f_: (lambda s, fr: f_(fr)))(desc[m])) for m in knobs]
    describe = timing.time_methods(dm, raw, {m: [] for m in knobs}, 3)
    mm = [timing.Method(m, methods[i].start, (lambda s, x: s.update_descriptor(x))) for i, m in enumerate(knobs)]
    X = {m: list(d.descriptors[k["descriptor"]][start:stop]) for m, k in knobs.items()}
    match = {}
    for m in mm:   # each its own descriptors
        match[m.name] = timing.time_methods([m], X[m.name], {m.name: preload[m.name]}, 3)[0]
    for w in whole:
        m = w["method"]
        dsc = next(r for r in describe if r["method"] == m)
        print(json.dumps({"variant": m, "fps_min": round(w["fps_min"], 1), "fps_median": round(w["fps_median"], 1),
                          "fps_max": round(w["fps_max"], 1), "describe_ms_median": round(1e3 / dsc["fps_median"], 3),
                          "describe_ms_slowest": round(1e3 / dsc["fps_min"], 3),
                          "match_ms_median": round(1e3 / match[m]["fps_median"], 3),
                          "match_ms_slowest": round(1e3 / match[m]["fps_min"], 3),
                          "bytes_per_frame": dets[m].bytes_per_frame, "cpu": w["cpu"]}), flush=True)

if __name__ == "__main__":
    ds = sys.argv[1]
    run(ds, 3576 if "nordland" in ds else 200)
