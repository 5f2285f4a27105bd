"""``python -m greenloop sweep NOTEBOOK --grid NAME=V1,V2 ...``: argument parsing only; the run is
``greenloop.study.sweep``."""
from __future__ import annotations

import sys

from greenloop.study import sweep


def add_parser(sub) -> None:
    """The ``sweep`` subcommand's arguments."""
    s = sub.add_parser("sweep", help="run a notebook over a parameter grid on Dask (local or cluster)",
                       description="Run NOTEBOOK once per point of the cross product of the grids, each point a "
                                   "papermill run on a Dask worker, into OUT/<point>/; assemble OUT/sweep.csv, "
                                   "sweep.md and sweep.png. Points whose point.json says ok are not run again "
                                   "(an interrupted sweep resumes).")
    s.add_argument("notebook", metavar="NOTEBOOK", help="notebook with a cell tagged 'parameters'")
    s.add_argument("--grid", action="append", required=True, metavar="NAME=V1,V2,...",
                   help="a swept parameter; values are YAML (20, 0.5, null, [0,1], text); repeat for a cross product")
    s.add_argument("--out", required=True, help="sweep folder, e.g. results/sweep/NAME")
    s.add_argument("-f", "--parameters-file", action="append", default=[], metavar="YAML",
                   help="parameters for every point (e.g. params/quick.yaml); repeatable")
    s.add_argument("-p", "--parameter", action="append", nargs=2, default=[], metavar=("NAME", "VALUE"),
                   help="one parameter for every point (VALUE read as YAML); repeatable")
    s.add_argument("--dataset", default=str(sweep.DEFAULT_DATASET),
                   help="sequence folder injected as `dataset` (default data/synthetic-greenhouse)")
    s.add_argument("--scheduler", default="local",
                   help="local (a LocalCluster, default), a scheduler address (tcp://host:8786), or slurm / pbs "
                        "(dask-jobqueue; see --queue ...)")
    s.add_argument("--workers", type=int, default=None, help="local: worker processes (default one per 4 cores); slurm/pbs: jobs")
    s.add_argument("--metric", action="append", default=[], metavar="SPEC",
                   help="numbers for the table: a summary.json key (a.b), FILE.csv:COLUMN or FILE.csv[KEY=VALUE]:COLUMN; "
                        "the first is plotted; repeatable")
    s.add_argument("--x", default=None, help="swept parameter on the figure's x axis (default: the first numeric one)")
    s.add_argument("--cache", default=None, help="model cache shared by every point (default $GREENLOOP_CACHE or results/models)")
    s.add_argument("--force", action="store_true", help="run complete points again")
    s.add_argument("--retries", type=int, default=1, help="reruns of a failed point (default 1)")
    s.add_argument("--timeout", type=int, default=7200, help="per-cell timeout, s (default 7200)")
    s.add_argument("--kernel", default="greenloop", help="Jupyter kernel (default greenloop)")
    q = s.add_argument_group("slurm / pbs jobs (default: the dask config jobqueue.<kind>.*)")
    q.add_argument("--queue", help="partition / queue")
    q.add_argument("--cores", type=int, help="cores per job (one point runs per job at a time)")
    q.add_argument("--memory", help="memory per job, e.g. 16GB")
    q.add_argument("--walltime", help="job wall time, e.g. 04:00:00")
    q.add_argument("--account", help="account / project to charge")
    q.add_argument("--job-extra", action="append", default=None, metavar="DIRECTIVE",
                   help="extra job-script directive, e.g. --job-extra=--gres=gpu:1; repeatable")
    s.set_defaults(func=run)


def run(args) -> int:
    """One papermill run per grid point on Dask; 0 when every point is ok, else 1."""
    base, warnings = sweep.base_parameters(args.notebook, args.dataset, args.parameters_file, args.parameter)
    for line in warnings:
        print(line, file=sys.stderr)
    options = dict(queue=args.queue, cores=args.cores, memory=args.memory, walltime=args.walltime,
                   account=args.account, job_extra_directives=args.job_extra)
    try:
        table = sweep.run_sweep(args.notebook, sweep.parse_grid(args.grid), args.out, base=base, dataset=args.dataset,
                                scheduler=args.scheduler, workers=args.workers, cache=args.cache, metrics=args.metric,
                                x=args.x, force=args.force, timeout=args.timeout, kernel=args.kernel,
                                retries=args.retries, cluster_options=options)
    except KeyboardInterrupt:
        print(f"sweep: interrupted; the finished points in {args.out} are kept: run the same command again to resume",
              file=sys.stderr)
        return 130
    return 0 if (table.status == "ok").all() else 1
