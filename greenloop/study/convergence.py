"""The one definition of a converged seed per model family, and the one count of a spot CNN run's
converged seeds, read from the run's own table (``verdict`` judges with it, ``summary`` prints it).

A spot CNN seed converged when its final training accuracy reached :data:`CONVERGED_AT` % or its
training accuracy stopped rising before the epoch cap (``training_over_seeds.converged``, which the
notebooks apply per seed and write into ``01_spot_grouping/table1.csv``'s converged_seeds and
``02_training_over_seeds/per_seed.csv``'s converged). Each run is counted on its own table: notebook
01's runs for Table 1, notebook 02's (whose models 03 and 04 test) for everything else.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import NamedTuple

import pandas as pd

CONVERGED_AT = 95                  # % final training accuracy: a spot CNN seed fit its training frames
CONVERGED = {
    "spot CNN": (f"a seed converged when its final training accuracy reached {CONVERGED_AT} % (it fit its training "
                 "frames) or its training accuracy stopped rising before the epoch cap (early stopping); counted per "
                 "trained run (01's for Table 1; 02's, whose models 03 and 04 test, for Fig. 3-4, Fig. 5 and Table 3; "
                 "the dictionary's CNN is trained as 02's, its count is 02's)"),
    "Siamese network": "its training loss stopped falling within its epochs",
}


def read_table(folder: Path, name: str) -> pd.DataFrame | None:
    """A folder's table with "%" in column names read as "pct" (``acc_mean_%`` -> ``acc_mean_pct``), or None."""
    path = folder / name
    if not path.is_file():
        return None
    t = pd.read_csv(path)
    t.columns = [c.replace("%", "pct") for c in t.columns]
    return t


def fmt(x) -> str:
    """A number as the tables print it: up to two decimals, no trailing zeros."""
    return f"{round(float(x), 2):g}"


class Convergence(NamedTuple):
    """How many of a trained run's seeds converged (:data:`CONVERGED`'s definition of the family):
    ``converged`` of ``seeds``; ``training``: how they were trained, as the cell says it."""
    converged: int
    seeds: int
    training: str

    def text(self) -> str:
        """"k of n seeds converged (training)", the wording of every row of the family."""
        return f"{self.converged} of {self.seeds} seeds converged ({self.training})"


def parameters(folder: Path, notebook: str) -> dict:
    """The parameters a notebook ran with (its manifest.json's "parameters"; {} where absent)."""
    path = Path(folder) / notebook / "manifest.json"
    return json.loads(path.read_text()).get("parameters", {}) if path.is_file() else {}


def training_text(folder: Path, notebook: str, lo=None, hi=None) -> str:
    """How a notebook's spot CNN seeds were trained, from its manifest's parameters and, where the
    table gives them, the epochs taken (``lo``..``hi``)."""
    p = parameters(folder, notebook)
    if p.get("stop_patience"):
        taken = f", {between(lo, hi)} epochs taken" if lo is not None else ""
        return f"trained until the training accuracy stopped rising, at most {p.get('stop_cap')} epochs{taken}"
    return f"{p['epochs']} epochs" if "epochs" in p else "epochs not recorded"


def between(lo, hi) -> str:
    """A range of counts as "lo-hi", or the one count where lo equals hi (``wording.between``)."""
    return f"{int(lo)}" if int(lo) == int(hi) else f"{int(lo)}-{int(hi)}"


def spot_cnn_convergence(folder: Path, run: str, frames_per_spot=None) -> Convergence | None:
    """The one count of converged spot CNN seeds (:data:`CONVERGED`), read from the run that trained
    them: ``run`` "01_spot_grouping" (``table1.csv``'s row at ``frames_per_spot``: its converged_seeds,
    which notebook 01 counts by ``training_over_seeds.converged`` per seed) or "02_training_over_seeds"
    (``per_seed.csv``'s random split, the same function per seed; 03 and 04 test these models).
    None where the table is missing."""
    if run == "01_spot_grouping":
        t = read_table(folder, "01_spot_grouping/table1.csv")
        if t is None or not (t.frames_per_spot == frames_per_spot).any():
            return None
        r = t[t.frames_per_spot == frames_per_spot].iloc[0]
        training = training_text(folder, run, r.get("epochs_min"), r.get("epochs_max"))
        low = r.get("final_train_acc_min_pct")
        return Convergence(int(r.converged_seeds), int(r.seeds),
                           training + ("" if low is None else f"; lowest final training accuracy {fmt(low)} %"))
    t = read_table(folder, "02_training_over_seeds/per_seed.csv")
    if t is None:
        return None
    t = t[t.split == "random"]
    acc = t.final_train_acc_pct
    return Convergence(int(t.converged.sum()), len(t),
                       f"{training_text(folder, run)}; final training accuracy [{fmt(acc.min())}, {fmt(acc.max())}] %")


def converged_flags(folder: Path, seeds) -> pd.Series:
    """Whether each of ``seeds`` (02's random-split seeds, the models 03 and 04 test) converged, as
    :func:`spot_cnn_convergence` counts them (False for a seed 02 did not train)."""
    t = read_table(folder, "02_training_over_seeds/per_seed.csv")
    done = {} if t is None else dict(zip(t[t.split == "random"].seed, t[t.split == "random"].converged))
    return pd.Series([bool(done.get(s, False)) for s in seeds], index=getattr(seeds, "index", None))


