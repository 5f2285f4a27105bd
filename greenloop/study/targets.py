"""The detector's targets, each as met / not met with its measured value, from one dataset's leaderboard rows.

A leaderboard row is a dict (or a pandas DataFrame row) with at least ``method`` and ``mode``
("loop closure" / "place recognition") and the per-query metrics in percent, named as notebook 13
writes them: ``R@1_%``, ``AUC-PR_%``, ``R@100P_%``; optionally ``fps_min`` (the slowest timing
repeat, frames/s) and ``closures_declared`` / ``closures_false`` (at the operating threshold).
Only what the rows hold is judged: a target whose value is absent is "not measured" (met None),
never met.

The target sets (evaluation part only, one configuration of greenloop-seq), TARGET_SETS; a dataset
names its set in its sequence.yaml (``protocol: {targets: ...}``, ``datasets.sequence.Sequence.protocol``,
the builders of Nordland and Gardens Point write it), and one that names none gets the generic set:
    nordland      R@1 >= 92 % with seq_len <= 10, R@100P >= 60 %, R@1 above the SeqSLAM row (loop closure)
    gardenspoint  R@1 >= 90 %, R@100P >= 50 % (place recognition: reference = the day traversal)
    generic       R@1 not below the best row (loop closure, chance excluded): the synthetic sequence, the
                  real GreenHouse set and users' own folders, whose few revisit queries give every row a
                  wide interval, so that no method can be shown highest there
    every set     >= 920 frames/s (slowest repeat); closure precision >= 90 % at the threshold used

"Above" and "not below" are judged from the paired comparisons where they are given (``comparisons``: the
table ``experiments.leaderboard.rows.comparisons`` writes, notebook 13's comparisons.csv; :func:`paired_ahead`): met
only where every paired difference (the method minus each other row, on the same queries) is resolved
above 0. Rows alone (no comparisons, e.g. a leaderboard.csv read back) compare their 95 % intervals
(``R@1_lo_%`` / ``R@1_hi_%``, the same for AUC-PR; :func:`separated`): met only where the method's
interval lies wholly above the other rows'. Either way a point estimate inside the spread is never
called ahead, and a comparison that is absent is not measured. "Not below" is met unless some paired
difference is resolved below 0 (:func:`paired_not_below`); from rows alone, where the method's interval
reaches the best other row's point value.

A paired interval is worded by one rule (:func:`paired_word`, :data:`PAIRED_RULE`, printed where a
table shows it): resolved where it excludes 0; a tie where both ends are exactly 0 (the same on every
resample); uninformative where one end lands exactly on 0 (a block bootstrap over few blocks, ten on 91
queries, puts a bound on a whole block's difference: 0 there shows neither an order nor its absence);
not resolved where it holds 0 strictly inside. A target judged on an uninformative pair is neither
met nor not met (met None, the target says why).
"""
from __future__ import annotations

import math

__all__ = ["FPS_TARGET", "PAIRED_RULE", "PRECISION_TARGET", "TARGET_SETS", "detector_targets", "met_word", "paired_ahead",
           "paired_not_below", "paired_word", "separated"]

RESOLVED, TIE, UNINFORMATIVE, NOT_RESOLVED = "resolved", "tie", "uninformative", "not resolved"
PAIRED_RULE = (f"Paired intervals (a minus b on the same queries, 95 % block bootstrap): {RESOLVED} where the "
               f"interval excludes 0; {TIE} where both ends are exactly 0; {UNINFORMATIVE} where one end lands "
               f"exactly on 0 (a bootstrap over few blocks puts a bound on a whole block's difference); "
               f"{NOT_RESOLVED} where 0 lies strictly inside.")
FPS_TARGET = 920.0            # frames/s per stream on 2 cores, descriptor included (the main paper's)
PRECISION_TARGET = 90.0       # % closure precision at the one threshold


def _rows(rows) -> list[dict]:
    if hasattr(rows, "to_dict"):
        rows = rows.to_dict("records")
    return [dict(r) for r in rows]


def _value(row, key):
    v = None if row is None else row.get(key)
    return None if v is None or (isinstance(v, float) and math.isnan(v)) else float(v)


def _judge(target: str, measured, required: str, ok) -> dict:
    """One target: met None when the value is absent (not measured) or ``ok`` answers None (undecided)."""
    met = None if measured is None else ok(measured)
    return {"target": target, "measured": measured, "required": required, "met": None if met is None else bool(met)}


def paired_word(lo, hi) -> str:
    """The one wording of a paired interval [lo, hi] (points, a minus b; module doc, :data:`PAIRED_RULE`):
    "resolved" (excludes 0), "tie" (both ends exactly 0), "uninformative" (one end exactly 0) or
    "not resolved" (0 strictly inside). Raises ValueError for a missing end."""
    if lo is None or hi is None or lo != lo or hi != hi:
        raise ValueError(f"a paired interval needs both ends, got [{lo}, {hi}]: read lo and hi from comparisons.csv")
    lo, hi = float(lo), float(hi)
    if lo > 0 or hi < 0:
        return RESOLVED
    if lo == 0 and hi == 0:
        return TIE
    return UNINFORMATIVE if lo == 0 or hi == 0 else NOT_RESOLVED


def met_word(row: dict) -> str:
    """A targets.csv row's "met" cell as the summary prints it: "uninformative" where the target is
    judged on a paired bound that lies exactly on 0 (:func:`paired_word`; rows written before the rule
    read met or not met there; the row holds that one end, so a tie reads uninformative too), else
    yes / no / "–" (not measured)."""
    measured = _value(row, "measured") if not isinstance(row.get("measured"), str) else (
        float(row["measured"]) if row["measured"].strip() not in ("", "nan") else None)
    if "paired differences" in str(row.get("target", "")) and measured == 0:
        return UNINFORMATIVE
    return {"true": "yes", "false": "no"}.get(str(row.get("met")).strip().lower(), "–")


def _find(rows, method: str, mode: str):
    hit = [r for r in rows if r.get("method") == method and r.get("mode") == mode]
    return hit[0] if hit else None


def _others(rows, method: str, mode: str, key: str) -> list:
    """The rows of ``mode`` other than ``method`` and chance that hold ``key``."""
    return [r for r in rows if r.get("mode") == mode and r.get("method") != method
            and not str(r.get("method", "")).startswith("chance") and _value(r, key) is not None]


def separated(row, others, key: str):
    """(low end of ``row``'s interval of ``key``, the highest high end among ``others``): ``row`` is
    above them all where the first exceeds the second. key: a metric column such as "R@1_%", whose
    interval is ``<key without %>lo_%`` / ``hi_%``. Rows are dicts; either value None where an
    interval is absent (or no other row is given)."""
    lo, hi = key[:-1] + "lo_%", key[:-1] + "hi_%"
    highs = [_value(r, hi) for r in others]
    top = None if not highs or any(h is None for h in highs) else max(highs)
    return _value(row, lo), top


def _pairs(comparisons, method: str, others, key: str, end: str):
    """The rows of ``comparisons`` for ``method`` minus each of ``others`` on ``key``'s metric, with
    ``end`` ("lo" / "hi") as a float; None where ``others`` is empty or one of them is absent."""
    rows = {r["b"]: r for r in _rows(comparisons) if r.get("a") == method and r.get("metric") == key[:-2]}
    names = [r.get("method") for r in others]
    if not names or any(n not in rows or _value(rows[n], end) is None for n in names):
        return None
    return [dict(rows[n], **{end: _value(rows[n], end)}) for n in names]


def paired_ahead(comparisons, method: str, others, key: str):
    """(the lowest low end, in percentage points, of the paired differences ``method`` minus each of
    ``others`` (rows with ``method``) on ``key``'s metric ("R@1_%": "R@1"); whether every one of
    them is resolved with ``method`` ahead (its ``resolved`` True and its interval above 0), None
    where that lowest low end is exactly 0: uninformative, :func:`paired_word`), read
    from ``comparisons`` (rows or a DataFrame with a, b, metric, lo, resolved, as
    ``experiments.leaderboard.rows.comparisons`` writes them). (None, False) where ``others`` is empty or the
    table lacks one of them."""
    pairs = _pairs(comparisons, method, others, key, "lo")
    if pairs is None:
        return None, False
    low = min(r["lo"] for r in pairs)
    if any(paired_word(r["lo"], _value(r, "hi")) == UNINFORMATIVE and r["lo"] == 0 for r in pairs):
        return low, None                                  # a low end exactly 0: uninformative (paired_word)
    return low, all(bool(r["resolved"]) and r["lo"] > 0 for r in pairs)


def paired_not_below(comparisons, method: str, others, key: str):
    """(the lowest high end, in points, of the paired differences ``method`` minus each of ``others`` on
    ``key``'s metric; whether none of them is resolved below 0, None where that lowest high end is
    exactly 0: uninformative, :func:`paired_word`), read from ``comparisons`` as :func:`paired_ahead` reads it. (None, False) where ``others`` is empty or the table lacks one."""
    pairs = _pairs(comparisons, method, others, key, "hi")
    if pairs is None:
        return None, False
    high = min(r["hi"] for r in pairs)
    if any(bool(r["resolved"]) and r["hi"] < 0 for r in pairs):
        return high, False
    if any(paired_word(_value(r, "lo"), r["hi"]) == UNINFORMATIVE and r["hi"] == 0 for r in pairs):
        return high, None                                 # a high end exactly 0: uninformative (paired_word)
    return high, True


def _not_below(target: str, row, others, key: str, comparisons=None) -> dict:
    """A target met where ``row`` is not below the best of ``others`` on ``key``: with ``comparisons``,
    no paired difference resolved below 0 (:func:`paired_not_below`: measured = the lowest high end);
    without, its interval's high end reaches the best other row's point value."""
    if comparisons is not None:
        high, ok = (None, False) if row is None else paired_not_below(comparisons, row.get("method"), others, key)
        return _judge(f"{target}: the lowest high end of its paired differences (points)", high,
                      ">= 0 (none resolved below; exactly 0: uninformative)", lambda v: ok)
    best = max((_value(r, key) for r in others), default=None)
    hi = _value(row, key[:-1] + "hi_%")
    return _judge(f"{target}: the high end of its interval", None if best is None else hi, f">= {best}",
                  lambda v: v >= best)


def _above(target: str, row, others, key: str, comparisons=None) -> dict:
    """A target met where ``row`` is above every one of ``others`` on ``key``: with ``comparisons``,
    every paired difference resolved above 0 (:func:`paired_ahead`: measured = the lowest low end,
    required "> 0, each resolved"); without, its interval wholly above theirs (:func:`separated`:
    measured = its low end, required = "> the others' highest high end")."""
    if comparisons is not None:
        low, ahead = (None, False) if row is None else paired_ahead(comparisons, row.get("method"), others, key)
        return _judge(f"{target}: the lowest low end of its paired differences (points)", low,
                      "> 0, each resolved (exactly 0: uninformative)", lambda v: ahead)
    lo, top = separated(row, others, key)
    return _judge(f"{target}: the low end of its interval", None if top is None else lo, f"> {top}", lambda v: v > top)


def _common(row, seq_len) -> list[dict]:
    out = [_judge("frames/s (slowest repeat)", _value(row, "fps_min"), f">= {FPS_TARGET:g}",
                  lambda v: v >= FPS_TARGET)]
    n, bad = _value(row, "closures_declared"), _value(row, "closures_false")
    prec = None if n is None or bad is None or n == 0 else 100.0 * (n - bad) / n
    out.append(_judge("closure precision at the threshold (%)", prec, f">= {PRECISION_TARGET:g}",
                      lambda v: v >= PRECISION_TARGET))
    return out


def detector_targets(rows, targets: str = "generic", method: str = "greenloop-seq", seqslam: str = "SeqSLAM",
                     seq_len=None, frame_step=None, comparisons=None) -> list[dict]:
    """Each target of the set ``targets`` (module doc; a dataset's ``Sequence.protocol.targets``) for ``method``:
    a list of dicts target (text), measured (float, % or frames/s; None when the rows do not hold it),
    required (text) and met (bool; None when not measured). rows: the dataset's leaderboard rows (list of
    dicts or a DataFrame). seqslam: the SeqSLAM row's method name, or several (each judged: Nordland's R@1
    above it). seq_len: the method's frames of sequence (needed for Nordland's "<= 10 frames"); frame_step:
    the rows' frame step (Nordland's targets are at its full rate, frame_step 1). comparisons: the paired
    comparisons that judge "above" and "highest" (module doc; None: the rows' intervals). Raises
    ValueError for a name that is none of TARGET_SETS."""
    if targets not in TARGET_SETS:
        raise ValueError(f"targets {targets!r} is none of the target sets {', '.join(TARGET_SETS)}: name one in the "
                         f"dataset's sequence.yaml (`protocol: {{targets: generic}}`), or leave it out for generic")
    rows = _rows(rows)
    lc, pr = _find(rows, method, "loop closure"), _find(rows, method, "place recognition")
    return TARGET_SETS[targets](rows, lc, pr, method, seqslam, seq_len, frame_step, comparisons)


def _nordland(rows, lc, pr, method, seqslam, seq_len, frame_step, comparisons) -> list[dict]:
    """Nordland's targets: at the full rate, R@1 and R@100P (loop closure), seq_len, above every SeqSLAM row."""
    r1 = _value(lc, "R@1_%")
    out = [_judge("frame step of the rows (1 = Nordland's full rate)", None if frame_step is None else float(frame_step),
                  "== 1", lambda v: v == 1),
           _judge("R@1 (%), loop closure", r1, ">= 92", lambda v: v >= 92.0),
           _judge("frames of sequence", None if seq_len is None else float(seq_len), "<= 10", lambda v: v <= 10),
           _judge("R@100P (%), loop closure", _value(lc, "R@100P_%"), ">= 60", lambda v: v >= 60.0)]
    for name in ([seqslam] if isinstance(seqslam, str) else list(seqslam)):
        other = _find(rows, name, "loop closure")
        sr = _value(other, "R@1_%")
        out.append(_above(f"R@1 above {name} ({sr if sr is not None else 'not measured'} %)", lc,
                          [] if other is None else [other], "R@1_%", comparisons))
    return out + _common(lc, seq_len)


def _gardenspoint(rows, lc, pr, method, seqslam, seq_len, frame_step, comparisons) -> list[dict]:
    """Gardens Point's targets: R@1 and R@100P in place recognition."""
    return [_judge("R@1 (%), place recognition", _value(pr, "R@1_%"), ">= 90", lambda v: v >= 90.0),
            _judge("R@100P (%), place recognition", _value(pr, "R@100P_%"), ">= 50", lambda v: v >= 50.0)] \
        + _common(lc if lc is not None else pr, seq_len)


def _generic(rows, lc, pr, method, seqslam, seq_len, frame_step, comparisons) -> list[dict]:
    """The generic targets: R@1 not below the best other row (loop closure, chance excluded)."""
    return [_not_below("R@1 not below the best row, loop closure", lc,
                       _others(rows, method, "loop closure", "R@1_%"), "R@1_%", comparisons)] + _common(lc, seq_len)


TARGET_SETS = {"generic": _generic, "nordland": _nordland, "gardenspoint": _gardenspoint}   # sequence.PROTOCOL_TARGETS
