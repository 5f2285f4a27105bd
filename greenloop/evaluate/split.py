"""The honest split: tuning and evaluation query frames that share no revisit (``greenloop.evaluate``'s
package doc, "Honest tuning"), and the note a notebook shows where no such split exists.
"""
from __future__ import annotations

import numpy as np

from greenloop.evaluate.metrics import _check_gt
from greenloop.groundtruth import revisit_frames
from greenloop.util.checks import positive_int

# ------------------------------------------------------------------------------ tuning
class NoHonestSplit(ValueError):
    """:func:`split_mask` found no cut that leaves revisit frames (or, without a ground truth,
    frames) on both sides of the gap. A ValueError, so code that caught the old errors still does.

    Attributes: n (frames), gap (frames kept free after the cut), revisits (number of revisit
    frames; None without a ground truth), first, last (frame index of the first and last revisit
    frame; None without one), span = last - first (frames; None without one).
    """

    def __init__(self, message: str, *, n: int, gap: int, revisits: int | None = None,
                 first: int | None = None, last: int | None = None):
        super().__init__(message)
        self.n, self.gap, self.revisits, self.first, self.last = n, gap, revisits, first, last
        self.span = None if first is None else last - first

    def statement(self, dropped: str = "the tuned rows", frames=None,
                  kept: str = "numbers that need no tuning are scored on every query instead") -> str:
        """The notebooks' one-paragraph note (Markdown) for this case: what is missing and why.

        dropped: what the caller does not report, e.g. "the tuned rows".
        kept: what it reports instead (a clause, no full stop).
        frames: optional (n,) original frame numbers of the split's frames (``np.arange(0, N,
            step)``), to name the revisit frames as original frames as well; the gap and the span
            are in the split's own frames (steps of ``step``).
        """
        if self.revisits is None:
            why = (f"the {self.n} frames cannot be cut with a gap of {self.gap} frames between the "
                   f"tuning and the evaluation part")
        else:
            unit = "frames" if frames is None else "described frames"
            where = f"{unit} {self.first}..{self.last}"
            if frames is not None:
                f = np.asarray(frames)
                where += f", original frames {int(f[self.first])}..{int(f[self.last])}"
            why = (f"the {self.revisits} revisit frame{'s' if self.revisits != 1 else ''} of this "
                   f"sequence ({where}) all lie within {self.span} {unit}, no more than the gap of "
                   f"{self.gap} {unit} kept free between the tuning and the evaluation part; no "
                   f"tune/score split keeps them apart")
        return f"**No honest tuning/evaluation split:** {why}, so {dropped} are not reported; {kept}."


def split_mask(n: int, fraction: float = 0.5, gt=None, gap: int = 0):
    """Two disjoint, contiguous sets of query frames: tune on one, report on the other.

    n: number of frames. fraction: share of the split that goes to the tuning part (0 < f < 1).
    gt: optional (n, n) bool ground truth. Without it, the requested cut is at frame
        round(fraction * n). With it, the requested cut is at the revisit frame rev[m],
        m = round(fraction * R) clipped to 1..R-1, where rev are the R *revisit frames* (frames
        with a loop partner earlier in the sequence, :func:`greenloop.groundtruth.revisit_frames`)
        in order: ``fraction`` of them before the cut. Use it when loops are rare or clustered
        (the GreenHouse set revisits only in frames ~2068-2260, so a plain cut at n/2 would leave
        the tuning part without any loop). Only labels are used, never scores.
    gap: frames right after the cut that belong to neither part (frames, >= 0), so that
        near-duplicate neighbours (and median-filter windows, use gap >= size) do not straddle it.

    The cut is the requested one when it leaves a revisit frame at or after cut + gap. Otherwise
    (revisits clustered at the end of the sequence, e.g. one loop closing in its last frames) it
    moves down to the latest cut that still does, last revisit frame - gap: the honest cut
    closest to the requested one, with as many revisit frames in the tuning part as the gap
    allows and at least the last one in the evaluation part. So with a ground truth both parts
    always hold a revisit frame and no revisit frame within ``gap`` after the cut is scored.
    An honest cut exists iff the revisit frames span more than the gap (last - first > gap);
    without a ground truth, iff n > gap + 1 (the cut is then at most n - 1 - gap).

    Returns (tune (n,) bool, evaluate (n,) bool): tune = frames before the cut, evaluate =
    frames from cut + gap on. Pass them as ``queries=`` to the scoring functions.
    Raises NoHonestSplit (a ValueError) when no honest cut exists, naming the number of revisit
    frames, their span and the gap; ValueError for bad arguments or a ground truth with no
    revisit frame at all.
    """
    n, gap = _check_split_args(n, fraction, gap)
    cut = _plain_cut(n, fraction, gap) if gt is None else _revisit_cut(n, fraction, gt, gap)
    idx = np.arange(n)
    return idx < cut, idx >= cut + gap


def _check_split_args(n, fraction, gap) -> tuple[int, int]:
    """``split_mask``'s n (frames, >= 2) and gap (frames, >= 0) as ints; ValueError when n, gap
    or fraction (strictly between 0 and 1) is out of range."""
    positive_int("n", n, 2, unit="frames")
    if not 0 < fraction < 1:
        raise ValueError(f"fraction must be strictly between 0 and 1, got {fraction}")
    positive_int("gap", gap, 0, unit="frames")
    return int(n), int(gap)


def _plain_cut(n: int, fraction: float, gap: int) -> int:
    """The cut (a frame index) without a ground truth: round(fraction * n), clipped to 1..n-1 and
    to at most n - 1 - gap; NoHonestSplit when that leaves no frame before it."""
    cut = min(min(max(int(round(fraction * n)), 1), n - 1), n - 1 - gap)
    if cut < 1:
        raise NoHonestSplit(
            f"{n} frames cannot be split with a gap of {gap} frames: a split needs a frame "
            f"before the cut and one at or after cut + gap, so n must exceed gap + 1",
            n=n, gap=gap)
    return cut


def _revisit_cut(n: int, fraction: float, gt, gap: int) -> int:
    """The cut (a frame index) on the revisit frames of gt (n, n) bool: at revisit frame rev[m],
    m = round(fraction * R) clipped to 1..R-1, moved down to at most last revisit - gap.
    ValueError without revisit frames, NoHonestSplit when they span no more than the gap."""
    G = _check_gt(gt)
    if G.shape[0] != n:
        raise ValueError(f"gt has shape {G.shape} but n={n}")
    rev = np.flatnonzero(revisit_frames(G))
    if rev.size == 0:
        raise ValueError("the ground truth has no revisit frame (no frame has a loop partner "
                         "earlier in the sequence): the sequence may not revisit any place")
    first, last = int(rev[0]), int(rev[-1])
    if last - first <= gap:
        raise NoHonestSplit(
            f"the {rev.size} revisit frame(s) of this sequence all lie within {last - first} "
            f"frames (frames {first}..{last}), not more than the gap of {gap} frames kept free "
            f"between the tuning and the evaluation part: no split keeps revisits on both sides "
            f"(it needs one before the cut and one at or after cut + gap, so their span must "
            f"exceed the gap)", n=n, gap=gap, revisits=int(rev.size), first=first, last=last)
    m = min(max(int(round(fraction * rev.size)), 1), rev.size - 1)
    return min(int(rev[m]), last - gap)     # rev[:m] tune when the requested cut is honest


# ------------------------------------------------------ the split's summary line
def honest_split(n: int, fraction: float, gt, gap: int, frames=None,
                 dropped: str = "the tuned rows",
                 kept: str = "numbers that need no tuning are scored on every query instead"):
    """:func:`split_mask` with its no-split case turned into the notebooks' note.

    n, fraction, gt, gap: as :func:`split_mask` (gap in frames of the split). frames, dropped,
    kept: as :meth:`NoHonestSplit.statement`. Returns (tune (n,) bool, evaluate (n,) bool, None)
    when an honest cut exists, else (None, None, note): the Markdown paragraph saying what is not
    reported and why; ``queries=None`` (every query) is then what untuned rows are scored on.
    """
    try:
        tune, evaluate = split_mask(n, fraction, gt=gt, gap=gap)
    except NoHonestSplit as e:
        return None, None, e.statement(dropped, frames, kept=kept)
    return tune, evaluate, None


def split_summary(tune, evaluate, gt, gap: int) -> str:
    """One line naming the two query parts of :func:`split_mask`: their frames and revisit frames.

    tune, evaluate: (N,) bool masks; gt: (N, N) bool ground truth; gap: the split's gap (frames).
    """
    rev = revisit_frames(_check_gt(gt))
    cut = int(np.flatnonzero(tune)[-1]) + 1
    return (f"tuning queries: frames 0..{cut - 1} ({int(rev[tune].sum())} revisit frames); "
            f"evaluation queries: frames {cut + gap}..{len(tune) - 1} ({int(rev[evaluate].sum())} "
            f"revisit frames); gap {gap}")
