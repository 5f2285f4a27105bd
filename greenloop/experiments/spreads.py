"""How the notebooks' generated conclusions word a number with its spread, and an order.

Each notebook of 07-13 ends with ``<module>.conclusion(out_dir)``: :func:`heading` (the verdicts of
the papers' claims it concludes on, ``study.verdict.conclusion``) and sentences built here. The
rules are the verdict's (``study.verdict.RULES``): an order ("above", "below") is said only where
the two spreads separate and each arm has at least ``verdict.MIN_SEEDS`` samples; separated spreads
with fewer samples, overlapping spreads and single values without spread are "not resolved" /
"not a ranking". Colours: :func:`palette`, one per method. Paper values on a figure:
:func:`mark_paper` (a dashed marker with its legend entry).
"""
from __future__ import annotations

from pathlib import Path

from greenloop.study import verdict

NOT_A_RANKING = "single values without spread, not a ranking"


def num(x, unit: str = "") -> str:
    """A number as the tables print it: up to two decimals, no trailing zeros, then ``unit``
    (e.g. " %"); "n/a" for NaN or None."""
    try:
        x = float(x)
    except (TypeError, ValueError):
        return "n/a"
    return "n/a" if x != x else f"{round(x, 2):g}{unit}"


def span(lo, hi, unit: str = "") -> str:
    """'[lo, hi]' followed by ``unit``."""
    return f"[{num(lo)}, {num(hi)}]{unit}"


def heading(out_dir, stem: str) -> str:
    """The conclusion's first lines: '**Conclusion on <dataset>.**' and, where the notebook
    ``stem`` concludes on a claim of ``study.verdict.CLAIMS``, its verdict bullets for the
    dataset of ``out_dir.parent`` (the notebook's results folder)."""
    folder = Path(out_dir).parent
    bullets = verdict.conclusion(folder, stem)
    return f"**Conclusion on {verdict.dataset_name(folder)}.**" + (f"\n\n{bullets}" if bullets else "")


def order(a: str, arm_a, b: str, arm_b, samples: str = "seeds", min_n: int = verdict.MIN_SEEDS,
          words=("lies above", "lies below")) -> str:
    """A sentence piece comparing a and b, each (n, lo, hi): n samples (``samples``: "seeds",
    "hyperplane seeds", ...) whose spread is [lo, hi]. "a lies above b" (``words``) only where the
    spreads separate and both n >= ``min_n`` (the verdict's MIN_SEEDS for seed ranges); "... in every
    one of the n <samples>, but fewer than min_n per arm: not resolved" where they separate with
    fewer; "not resolved (the spreads overlap)" otherwise. a, b: the arms as the reader should see
    them (names with their numbers)."""
    (na, la, ha), (nb, lb, hb) = arm_a, arm_b
    side = words[0] if la > hb else words[1] if ha < lb else None
    if side is None:
        return f"{a} and {b}: not resolved (the spreads overlap)"
    n = int(min(na, nb))
    if n < min_n:
        return f"{a} {side} {b} in every one of the {n} {samples}, but fewer than {min_n} per arm: not resolved"
    return f"{a} {side} {b} (the spreads separate)"


def palette(names) -> dict:
    """{name: colour}: one distinct colour per name, in the order given (tab20, then tab20b and
    tab20c: up to 60 names), so that a method keeps its colour across a notebook's panels."""
    import matplotlib.pyplot as plt
    colours = [plt.get_cmap(m)(i) for m in ("tab20", "tab20b", "tab20c") for i in range(20)]
    return {n: colours[k % len(colours)] for k, n in enumerate(dict.fromkeys(names))}


def mark_paper(ax, x, y, label: str, horizontal: bool = True, width: float = 0.8):
    """The paper's value(s) on ``ax``: a dashed black segment of ``width`` centred on each (x, y)
    (horizontal bars: along x; ``horizontal`` False: a dashed vertical segment at x = y for barh),
    one legend entry ``label``. x, y: sequences of equal length (bar positions, values)."""
    first = True
    for xi, yi in zip(x, y):
        if yi is None or yi != yi:
            continue
        seg = ([xi - width / 2, xi + width / 2], [yi, yi]) if horizontal else ([yi, yi], [xi - width / 2, xi + width / 2])
        ax.plot(*seg, color="k", ls="--", lw=1.6, label=label if first else None, zorder=4)
        first = False
