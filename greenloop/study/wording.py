"""Sentences about measured numbers and their spread, for the conclusions the notebooks generate.

A notebook's last cell (``experiments.<study>.conclusion``) says what its tables show on the dataset it
ran on. These helpers word a number with its spread and an order between arms only where the spreads
separate it, by :mod:`greenloop.study.verdict`'s rule (at least ``verdict.MIN_SEEDS`` seeds per arm
and seed ranges that do not overlap); everything else reads "not resolved".
"""
from __future__ import annotations

from pathlib import Path

from greenloop.study import verdict

UNRESOLVED = verdict.UNRESOLVED


NOT_A_RANKING = "single values without spread, not a ranking"


def num(x, places: int = 2, unit: str = "") -> str:
    """A number as the tables print it: rounded to ``places`` decimals, no trailing zeros, then
    ``unit`` (e.g. " %"); "n/a" for NaN, None or text."""
    try:
        x = float(x)
    except (TypeError, ValueError):
        return "n/a"
    return "n/a" if x != x else f"{round(x, places):g}{unit}"


def span(lo, hi, places: int = 2, unit: str = "") -> str:
    """A range as "[lo, hi]" (numbers by :func:`num`) then ``unit``, or the one number where both
    print alike."""
    a, b = num(lo, places), num(hi, places)
    return (a if a == b else f"[{a}, {b}]") + unit


between = verdict.between          # a range of counts as "lo-hi" (one definition, in verdict)


def count(n, noun: str) -> str:
    """n and the noun, plural unless n is 1: "1 seed", "3 seeds"."""
    return f"{int(n)} {noun}" + ("" if int(n) == 1 else "s")


def signed(x, places: int = 2) -> str:
    """A difference with its sign: "+1.5", "-0.2", "0"."""
    v = round(float(x), places)
    return f"{v:+g}" if v else "0"


def order(arms: dict[str, tuple[int, float, float]], min_seeds: int = verdict.MIN_SEEDS) -> str:
    """Which arm ranks first, as far as the seed ranges say: ``arms`` maps a name to (seeds, min, max)
    of one metric (higher ranks first). Returns a clause: "resolved: a > b > c (the ranges do not
    overlap)", "resolved for the first only: ...", or "not resolved: ..." (overlapping ranges, or
    separate ones with fewer than ``min_seeds`` seeds in some arm)."""
    if len(arms) < 2:
        return f"{UNRESOLVED}: one arm only"
    ranked = sorted(arms, key=lambda k: (arms[k][1] + arms[k][2]) / 2, reverse=True)
    apart = [arms[a][1] > arms[b][2] for a, b in zip(ranked, ranked[1:])]
    first = arms[ranked[0]][1] > max(arms[k][2] for k in ranked[1:])
    if not first:
        return f"{UNRESOLVED}: the ranges overlap"
    if min(v[0] for v in arms.values()) < min_seeds:
        others = f"{ranked[1]}'s" if len(ranked) == 2 else "the others'"
        return f"{UNRESOLVED}: {ranked[0]}'s range lies apart from {others}, but with fewer than {min_seeds} seeds in an arm"
    if all(apart):
        return f"resolved: {' > '.join(ranked)} (the ranges do not overlap)"
    return f"resolved for the first only: {ranked[0]} above every other range; the rest overlap"


def sign(lo, hi, seeds: int, min_seeds: int = verdict.MIN_SEEDS) -> str:
    """The sign of a per-seed difference whose range over ``seeds`` seeds is [lo, hi]: "above zero in
    every seed" / "below zero in every seed" with at least ``min_seeds`` seeds; with fewer, the one sign
    is said with the count and left not resolved; "sign not resolved" where the range holds zero."""
    if lo > 0 or hi < 0:
        side = "above" if lo > 0 else "below"
        if seeds < min_seeds:
            return f"{side} zero in each of {count(seeds, 'seed')}, too few to resolve the sign, {min_seeds} needed"
        return f"{side} zero in every seed"
    return f"sign {UNRESOLVED}, the seeds fall on both sides of zero"


def pair_order(a: str, arm_a, b: str, arm_b, samples: str = "seeds", min_n: int = verdict.MIN_SEEDS,
               words=("lies above", "lies below")) -> str:
    """A sentence piece comparing a and b, each (n, lo, hi): n samples (``samples``: "seeds",
    "hyperplane seeds", ...) whose spread is [lo, hi]. "a lies above b" (``words``) only where the
    spreads separate and both n >= ``min_n``; "... in every one of the n <samples>, but fewer than
    min_n per arm: not resolved" where they separate with fewer; "not resolved (the spreads overlap)"
    otherwise. a, b: the arms as the reader should see them (names with their numbers)."""
    (na, la, ha), (nb, lb, hb) = arm_a, arm_b
    side = words[0] if la > hb else words[1] if ha < lb else None
    if side is None:
        return f"{a} and {b}: {UNRESOLVED} (the spreads overlap)"
    n = int(min(na, nb))
    if n < min_n:
        return f"{a} {side} {b} in every one of the {n} {samples}, but fewer than {min_n} per arm: {UNRESOLVED}"
    return f"{a} {side} {b} (the spreads separate)"


def heading(results_dir, notebook: str) -> str:
    """A conclusion's first lines: "### Conclusion on <dataset of results_dir>" and the verdicts of
    the claims ``notebook`` concludes on (``verdict.conclusion``), where it has any."""
    bullets = verdict.conclusion(Path(results_dir), notebook)
    return f"### Conclusion on {verdict.dataset_name(Path(results_dir))}" + (f"\n\n{bullets}" if bullets else "")


def compose(results_dir, notebook: str, sentences) -> str:
    """A notebook's conclusion as Markdown: :func:`heading`, then the sentences (empty ones left
    out) as one paragraph."""
    body = " ".join(s for s in sentences if s)
    return heading(results_dir, notebook) + (f"\n\n{body}" if body else "") + "\n"
