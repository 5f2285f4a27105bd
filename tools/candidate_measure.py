"""How close greenloop-seq's candidate mode (``--index``) stays to the exact scan on a real stream.

The named default configuration (``seqmatch.DEFAULT_KNOBS`` at ``DEFAULT_THRESHOLD``) streamed over
Nordland's 64x32 frames (data/nordland: summer frames START..START+N-1 then the same places in
winter, 2N frames, every winter frame a revisit of the summer frame N frames back), once scoring
every stored frame (the exact scan, ``seqstream.Detector(index=None)``) and once per index kind in
candidate mode (k rows per shifted query, the index reduced to ``seqstream.INDEX_DIM`` dims). Per
candidate mode, over the frames that have candidates:

* the best candidate's calibrated score against the exact scan's: median and p95 of |difference|;
* best match: the share of frames whose best candidate is within +-2 frames of the exact scan's,
  over all of them and over the revisit (winter) frames;
* events at the fixed threshold: the share of frames where both declare or both stay silent, and
  of the frames both declare, the share with the same match within +-2 frames;
* p50 / p99 ms per frame (the whole decision, descriptor given) on this machine, as loaded as it is.

A drive that never comes back (summer frames only, 2N of them or as many as there are) is
streamed too: the closures each mode declares there (all false).

    PYTHONPATH=. .venv/bin/python tools/candidate_measure.py [--nordland data/nordland] [--n 750]
        [--start 0] [--k 10] [--kinds scan hnsw ivf] [--null-sample 64] [--exclude 150]

Numbers printed, not written: results/ holds the committed tables only.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from greenloop.methods.greenloop_seq import seqmatch  # noqa: E402
from greenloop.methods.lsh import retrieval  # noqa: E402
from greenloop.methods.greenloop_seq import seqstream  # noqa: E402
from greenloop.util.threads import one_blas_thread  # noqa: E402

WINTER = 3576          # data/nordland: winter frame k is frame 3576 + k


def stream(det, X) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Feed X (N, D) to det one frame per call: (best match (N,) int64, -1 without candidates; its
    score (N,), NaN without; seconds per frame (N,); {frame: match} of the events)."""
    best, score, secs = np.full(len(X), -1), np.full(len(X), np.nan), np.zeros(len(X))
    with one_blas_thread():
        for j, x in enumerate(X):
            t0 = time.perf_counter()
            det.update_descriptor(x)
            secs[j] = time.perf_counter() - t0
            best[j], score[j] = seqstream.best_candidate(det)
    return best, score, secs, {e["frame"]: e["match"] for e in det.events}


def compare(ref, got, revisit) -> dict:
    """The agreement of a candidate-mode stream ``got`` with the exact scan's ``ref`` (both from
    :func:`stream`) over the frames with candidates; revisit (N,) bool: the frames that revisit a
    stored place (best matches compared there too)."""
    (b0, s0, _, e0), (b1, s1, secs, e1) = ref, got
    has = b0 >= 0
    d = np.abs(s1[has] - s0[has])
    both = sorted(set(e0) & set(e1))
    fired = [np.isin(np.arange(len(b0)), list(e)) for e in (e0, e1)]
    near = np.abs(b1 - b0) <= 2
    return {"frames": int(has.sum()), "|d score| p50": float(np.median(d)), "|d score| p95": float(np.quantile(d, 0.95)),
            "best +-2 %": 100 * float(near[has].mean()),
            "best +-2 % (revisits)": 100 * float(near[has & revisit].mean()) if (has & revisit).any() else float("nan"),
            "closures exact": len(e0), "closures cand": len(e1),
            "both declare or both silent %": 100 * float(np.mean(fired[0][has] == fired[1][has])),
            "same match +-2 % of both": 100 * float(np.mean([abs(e0[j] - e1[j]) <= 2 for j in both])) if both else float("nan"),
            "p50 ms": 1e3 * float(np.median(secs)), "p99 ms": 1e3 * float(np.quantile(secs, 0.99))}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--nordland", default="data/nordland", help="the built Nordland folder (make nordland)")
    p.add_argument("--n", type=int, default=750, help="summer frames, then as many winter ones")
    p.add_argument("--start", type=int, default=0)
    p.add_argument("--k", type=int, default=10, help="rows retrieved per shifted query")
    p.add_argument("--kinds", nargs="+", default=["scan", "hnsw", "ivf"], choices=retrieval.KINDS)
    p.add_argument("--null-sample", type=int, default=seqstream.NULL_SAMPLE)
    p.add_argument("--exclude", type=int, default=150)
    a = p.parse_args(argv)
    knobs, threshold = seqmatch.NAMED[seqmatch.DEFAULT_NAME]
    knobs = {k: v for k, v in knobs.items() if k != "descriptor"}
    rgb = Path(a.nordland) / "rgb"
    frames = [rgb / f"{a.start + k}.png" for k in range(a.n)] + [rgb / f"{WINTER + a.start + k}.png" for k in range(a.n)]
    once = [rgb / f"{k}.png" for k in range(a.start, min(a.start + 2 * a.n, WINTER))]     # summer only
    print(f"# {seqmatch.DEFAULT_NAME} at {threshold:g}, exclude {a.exclude}, k {a.k}, index {seqstream.INDEX_DIM} dims "
          f"(PCA on the first {seqstream.INDEX_FIT} candidate rows), null sample {a.null_sample}")
    retrieval.one_thread()
    for label, paths, revisit in ((f"Nordland summer {a.start}..{a.start + a.n - 1} then winter", frames, np.arange(2 * a.n) >= a.n),
                                  (f"no revisit: Nordland summer {a.start}..{a.start + len(once) - 1}", once, np.zeros(len(once), bool))):
        X = seqmatch.describe_frames([_read(q) for q in paths], seqmatch.DEFAULT_KNOBS["descriptor"])
        ref = stream(seqstream.Detector(threshold, exclude=a.exclude, **knobs), X)
        print(f"{label}: {len(X)} frames; exact scan: {len(ref[3])} closures, p50 {1e3 * np.median(ref[2]):.3g} ms, "
              f"p99 {1e3 * np.quantile(ref[2], 0.99):.3g} ms", flush=True)
        for kind in a.kinds:
            opts = {"nlist": 16, "train_size": 640} if kind == "ivf" else {}
            det = seqstream.Detector(threshold, exclude=a.exclude, index=kind, k=a.k, index_dim=seqstream.INDEX_DIM,
                                     null_sample=a.null_sample, index_options=opts, **knobs)
            r = compare(ref, stream(det, X), revisit)
            print(f"  {kind}: " + ", ".join(f"{key} {v:.4g}" if isinstance(v, float) else f"{key} {v}"
                                             for key, v in r.items()), flush=True)
    return 0


def _read(path: Path) -> np.ndarray:
    import cv2
    img = cv2.imread(str(path))
    if img is None:
        raise FileNotFoundError(f"{path}: build Nordland first (make nordland)")
    return img


if __name__ == "__main__":
    raise SystemExit(main())
