"""``python -m greenloop notebook-params NOTEBOOK DATASET RESULTS --out TMP.ipynb [--params-out Y]
[--args-out A] -- [papermill -f/-p arguments]``: make's step before each notebook (the work is
``greenloop.study.params.prepare_run`` and ``write_run``); exit 0 whether the notebook runs or is skipped."""
from __future__ import annotations

import sys

from greenloop.study import params


def add_parser(sub) -> None:
    """The ``notebook-params`` subcommand's arguments (everything after ``--`` is papermill's)."""
    s = sub.add_parser("notebook-params", help="make's step before a notebook: its parameters, or why it cannot run",
                       description="Write RESULTS/sequence_params.yaml; when NOTEBOOK cannot run on DATASET, write "
                                   "--out as a notebook that says why; else the run's papermill YAML (--params-out) "
                                   "and its other papermill options (--args-out, NUL-separated).",
                       epilog="after --: the papermill -f/-p arguments of the run (params/datasets/*.yaml, PARAMS)")
    s.add_argument("notebook")
    s.add_argument("dataset")
    s.add_argument("results")
    s.add_argument("--out", required=True, help="where the executed notebook goes (written only when skipped)")
    s.add_argument("--params-out", help="papermill YAML file of the run's parameters (written unless skipped)")
    s.add_argument("--args-out", help="the run's other papermill options, NUL-separated (written unless skipped)")
    s.set_defaults(func=run, takes_rest=True)


def run(a) -> int:
    """Prepare, print the notes (stdout) and undeclared names (stderr), write the run's files."""
    r = params.prepare_run(a.notebook, a.dataset, a.results, a.rest)
    if r.notes:                                  # once per run of make, not once per notebook
        print("\n".join(r.notes), flush=True)
    for line in r.undeclared:
        print(line, file=sys.stderr, flush=True)
    params.write_run(r, a.notebook, a.out, a.dataset, a.results, a.params_out, a.args_out)
    if r.reason or r.step_why:
        print(r.reason or r.step_why, flush=True)
    return 0
