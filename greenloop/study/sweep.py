"""Parameter sweeps of any notebook through Dask distributed: one papermill run per grid point.

``python -m greenloop sweep NOTEBOOK --grid name=v1,v2 [--grid ...] --out OUT`` (the CLI is in
``greenloop.__main__``) runs the cross product of the grids. Each point is one Dask task that runs
papermill on a worker (the notebook's kernel is a process of its own), on a LocalCluster by
default, on any running scheduler by address (``tcp://host:8786``), or on a SLURM or PBS cluster
through dask-jobqueue. Dask does the scheduling; this module only plans the points,
runs one, and assembles the table.

On disk, for a sweep of notebook ``NN_name`` into OUT::

    OUT/<point>/NN_name.ipynb        the executed notebook (papermill writes .tmp-NN_name.ipynb,
                                     renamed on success; to NN_name.failed.ipynb on failure)
    OUT/<point>/NN_name/             what the notebook wrote (it runs with results_dir = OUT/<point>)
    OUT/<point>/kernel.log           the kernel's own stdout and stderr (library start-up messages)
    OUT/<point>/point.json           parameters, status, attempts, wall time, error: written last, atomically
    OUT/sweep.csv, OUT/sweep.md      one row per point: its parameters and the numbers its notebook wrote
    OUT/sweep.png                    the swept quantity against the chosen metric

``<point>`` is the point's grid values as ``name=value`` joined by ``__``, each value written as a
YAML flow scalar as on the command line (``frames_per_spot_list=[40]__epochs=50``); a value with
characters unsafe in file names (spaces, slashes, quotes) is replaced by ``-`` and an 8-digit hash
of the parameters is appended, so the name stays deterministic and unique.

A point whose point.json says ``ok`` for the same notebook and parameters is complete and is not
run again, so an interrupted sweep resumes. A point that fails is retried once (in the same task),
then recorded as failed with its error; the other points go on. A worker that dies mid-point loses
only that point's attempt: Dask resubmits it elsewhere, and finished points are already on disk.
"""
from __future__ import annotations

import ast
import contextlib
import datetime as _dt
import hashlib
import itertools
import json
import os
import re
import shlex
import shutil
import socket
import sys
import threading
import time
import uuid
from pathlib import Path

import pandas as pd
import yaml

from greenloop import report
from greenloop.study import params as study_params
from greenloop.util.cache import CACHE_DIR, ROOT
DEFAULT_DATASET = ROOT / "data" / "synthetic-greenhouse"
TOPIC = "greenloop-sweep"            # Dask event topic: points report when they start and end
JOBQUEUE = ("slurm", "pbs")
START_TIMEOUT = 60                  # s for a point's kernel to answer (papermill's own default)
_SAFE = re.compile(r"[^A-Za-z0-9._+\-=,\[\]]+")
_METRIC = re.compile(r"^(?P<file>[^:\[\]]+\.csv)(?:\[(?P<key>[^=\]]+)=(?P<val>[^\]]*)\])?:(?P<col>.+)$")


# ----------------------------------------------------------------------------- the plan

def base_parameters(notebook, dataset, files=(), given=()) -> tuple[dict, list[str]]:
    """The parameters of every point, in increasing precedence: what the dataset implies (its
    sequence.yaml: ``study.params.sequence_parameters``, as make passes them), each YAML file of
    ``files``, each (name, YAML text) of ``given``. Returns (parameters, one warning line per name
    the notebook does not declare: a typo?)."""
    base = dict(study_params.sequence_parameters(dataset)[0]) if Path(dataset).is_dir() else {}
    for path in files:
        if not os.path.isfile(path):
            raise FileNotFoundError(f"parameters file {path} not found: pass a YAML file such as params/quick.yaml")
        base.update(yaml.safe_load(open(path)) or {})
    for name, value in given:
        base[name] = yaml.safe_load(value)
    if not Path(notebook).is_file():
        return base, []
    named = {**{k: path for path in files for k in yaml.safe_load(open(path)) or {}}, **{n: "-p" for n, _ in given}}
    return base, study_params.undeclared(named, notebook)


def parse_grid(specs) -> dict[str, list]:
    """``["name=v1,v2", ...]`` -> ``{"name": [v1, v2], ...}``, in the order given.

    Values are read as one YAML flow sequence, so each is a YAML scalar or flow collection:
    ``20`` (int), ``0.5`` (float), ``null`` (None), ``ghostnet`` (str), ``[0,1]`` (list).
    """
    grid: dict[str, list] = {}
    for spec in specs:
        name, sep, rhs = str(spec).partition("=")
        name = name.strip()
        if not sep or not name.isidentifier():
            raise ValueError(f"grid {spec!r} is not NAME=V1,V2,...: write e.g. --grid epochs=50,100")
        if name in grid:
            raise ValueError(f"grid {name!r} given twice: list all its values in one --grid {name}=...")
        try:
            values = yaml.safe_load(f"[{rhs}]")
        except yaml.YAMLError as e:
            raise ValueError(f"cannot read the values of grid {spec!r} as YAML ({e.problem}): quote "
                             f"strings that hold commas or colons, e.g. {name}='a,b'") from None
        if not values:
            raise ValueError(f"grid {name!r} has no values: write {name}=V1,V2,...")
        texts = [flow(v) for v in values]
        twice = [v for i, v in enumerate(values) if texts[i] in texts[:i]]
        if twice:
            raise ValueError(f"grid {name!r} has the value {flow(twice[0])} twice: each point runs once, "
                             f"list each value once")
        grid[name] = values
    if not grid:
        raise ValueError("no --grid given: name at least one parameter, e.g. --grid epochs=50,100")
    return grid


def flow(value) -> str:
    """A value as one-line YAML flow text, as typed on the command line: ``[40]``, ``0.5``, ``null``."""
    text = yaml.safe_dump(value, default_flow_style=True, width=1 << 20).strip()
    if text.endswith("..."):
        text = text[:-3].strip()
    return text.replace(", ", ",")


def point_name(values: dict) -> str:
    """The folder name of one point: ``name=value`` joined by ``__`` (see the module docstring)."""
    name = "__".join(f"{k}={flow(v)}" for k, v in values.items())
    if _SAFE.search(name) or len(name) > 150:
        digest = hashlib.sha1(json.dumps(values, sort_keys=True, default=str).encode()).hexdigest()[:8]
        name = _SAFE.sub("-", name)[:100] + "-" + digest
    return name


def notebook_parameters(notebook) -> dict[str, str]:
    """The notebook's cell tagged ``parameters``: ``{name: default value as source text}``.

    Read with Python's ``ast`` (an assignment per parameter; comments anywhere are fine).
    """
    try:
        nb = json.loads(Path(notebook).read_text())
    except ValueError as e:
        raise ValueError(f"{notebook} is not a readable notebook ({e}): pass an .ipynb file") from None
    for cell in nb.get("cells", []):
        if cell.get("cell_type") == "code" and "parameters" in cell.get("metadata", {}).get("tags", []):
            src = cell["source"] if isinstance(cell["source"], str) else "".join(cell["source"])
            try:
                tree = ast.parse(src)
            except SyntaxError as e:
                raise ValueError(f"{notebook}: its parameters cell is not valid Python ({e})") from None
            params = {}
            for node in tree.body:
                targets = node.targets if isinstance(node, ast.Assign) else (
                    [node.target] if isinstance(node, ast.AnnAssign) and node.value else [])
                for t in targets:
                    if isinstance(t, ast.Name):
                        params[t.id] = ast.get_source_segment(src, node.value) or ""
            return params
    raise ValueError(f"{notebook} has no cell tagged 'parameters': tag the first code cell "
                     f"'parameters' (papermill injects the sweep's values after it)")


def check_grid(grid: dict, params: dict, notebook) -> None:
    """Raise ValueError for a grid name the notebook does not have, for ``results_dir`` (set per
    point), and for scalar values given to a parameter whose default is a list."""
    for name, values in grid.items():
        if name == "results_dir":
            raise ValueError("results_dir cannot be swept: each point runs in its own folder under --out")
        if name == "dataset":
            continue
        if name not in params:
            raise ValueError(f"{Path(notebook).name} has no parameter {name!r}: its parameters are "
                             f"{', '.join(params)}")
        default = params[name].strip()
        bad = [v for v in values if v is not None and not isinstance(v, list)]
        if default.startswith("[") and bad:
            raise ValueError(f"{name} is a list in {Path(notebook).name} (default {default}); give each "
                             f"value as a list: --grid '{name}=" + ",".join(f"[{flow(v)}]" for v in values)
                             + "'")


def plan(grid: dict, out: Path, base: dict | None = None, dataset=DEFAULT_DATASET, notebook=None) -> list[dict]:
    """The points of the grid's cross product, in grid order.

    Returns a list of dicts: name (folder name), folder (absolute Path), values (the grid values of
    this point) and parameters (everything injected: base, dataset, the grid values, results_dir).
    Dataset paths (``--dataset`` or a swept ``dataset``) must exist; they are injected absolute.
    With ``notebook``, base keeps only the names its parameters cell declares (what the dataset
    implies and a shared params file hold names other notebooks read; papermill would warn "Passed
    unknown parameter" for each: greenloop.study.params.declared_only, as make does).
    """
    out = Path(out).resolve()
    if notebook is not None and base:
        base = study_params.declared_only(notebook, base)
    points = []
    for combo in itertools.product(*grid.values()):
        values = dict(zip(grid, combo))
        folder = out / point_name(values)
        params = {**(base or {}), "dataset": dataset, **values, "results_dir": str(folder)}
        path = Path(str(params["dataset"])).expanduser()
        if not path.exists():
            raise FileNotFoundError(f"dataset folder {path} not found: run `make synthetic` for the "
                                    f"default synthetic sequence, or pass --dataset PATH")
        params["dataset"] = str(path.resolve())
        points.append({"name": folder.name, "folder": folder, "values": values, "parameters": params})
    return points


def is_complete(point: dict, notebook) -> bool:
    """True when the point's point.json says ok for this notebook and these parameters."""
    try:
        rec = json.loads((point["folder"] / "point.json").read_text())
    except (OSError, ValueError):
        return False
    return (rec.get("status") == "ok" and rec.get("notebook") == str(notebook)
            and rec.get("parameters") == json.loads(json.dumps(point["parameters"], default=str)))


def point_env(cache=None) -> dict:
    """Environment every point's papermill and kernel get on top of the worker's: one shared model
    cache (``GREENLOOP_CACHE``, default $GREENLOOP_CACHE or results/models), this checkout on
    PYTHONPATH, TensorFlow's C++ logs off."""
    cache = Path(cache or CACHE_DIR).resolve()
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)
    return {"GREENLOOP_CACHE": str(cache), "PYTHONPATH": path, "TF_CPP_MIN_LOG_LEVEL": "2",
            "PYTHONUNBUFFERED": "1"}


# ----------------------------------------------------------------------------- one point (on a worker)

def _event(msg: dict) -> None:
    """Tell the client (progress) that a point started or ended; a no-op outside a Dask worker."""
    try:
        from distributed import get_worker
        get_worker().log_event(TOPIC, {**msg, "t": time.time()})
    except (ImportError, ValueError):
        pass


def _kernel_manager(log: Path):
    """A kernel manager class whose kernels write their stdout and stderr to ``log`` (TensorFlow's
    start-up lines stay out of the sweep's terminal and beside the point's results instead)."""
    from jupyter_client import AsyncKernelManager

    class PointKernelManager(AsyncKernelManager):
        async def start_kernel(self, **kw):
            with open(log, "ab") as fh:  # Popen keeps its own copy of the descriptor
                kw.setdefault("stdout", fh)
                kw.setdefault("stderr", fh)
                return await super().start_kernel(**kw)

    return PointKernelManager


def papermill_once(notebook, folder: Path, parameters: dict, env: dict, cwd, kernel: str,
                   timeout: int, start_timeout: int = START_TIMEOUT) -> str | None:
    """Execute the notebook once into ``folder`` with papermill (its kernel is a process of its
    own, started with the worker's environment updated by ``env``): ``timeout`` s per cell,
    ``start_timeout`` s for the kernel to answer. Returns None on success (``<stem>.ipynb`` in
    place), else the error text (``<stem>.failed.ipynb`` kept for reading)."""
    import papermill

    stem = Path(notebook).stem
    tmp = folder / f".tmp-{stem}.ipynb"
    os.environ.update(env)  # every point of a sweep has the same env: no need to restore it
    try:
        papermill.execute_notebook(str(notebook), str(tmp), parameters=parameters, kernel_name=kernel,
                                   cwd=str(cwd), execution_timeout=timeout, start_timeout=start_timeout,
                                   progress_bar=False,
                                   kernel_manager_class=_kernel_manager(folder / "kernel.log"))
    except papermill.PapermillExecutionError as e:
        error = f"{e.ename}: {e.evalue} (cell In [{e.exec_count}])"
    except Exception as e:  # the kernel died or timed out, the notebook is unreadable, ...
        error = f"{type(e).__name__}: {e}".strip()
    else:
        os.replace(tmp, folder / f"{stem}.ipynb")
        return None
    if tmp.is_file():
        os.replace(tmp, folder / f"{stem}.failed.ipynb")
    return error


def run_point(notebook, folder, values: dict, parameters: dict, env: dict, cwd=ROOT,
              kernel: str = "greenloop", timeout: int = 7200, retries: int = 1, force: bool = False,
              run: str = "", start_timeout: int = START_TIMEOUT) -> dict:
    """Run one sweep point (a Dask task): clear its folder, execute the notebook, retry a failure
    ``retries`` times, then write ``point.json`` last, atomically. Returns that record.
    A kernel that does not answer within ``start_timeout`` s is a failed attempt, retried too.

    A failing notebook never raises here: the record says ``"status": "failed"`` and the error.
    A point already complete is not run again unless ``force``, and never twice in one sweep
    ``run`` (Dask reruns a finished task whose result a dying worker still held).
    """
    folder = Path(folder)
    if is_complete({"folder": folder, "parameters": parameters}, notebook):
        rec = json.loads((folder / "point.json").read_text())
        if not force or rec.get("run") == run:
            return rec
    _event({"point": folder.name, "state": "start"})
    walls, error, attempt = [], None, 0
    for attempt in range(1, retries + 2):
        if folder.exists():
            shutil.rmtree(folder)
        folder.mkdir(parents=True)
        t0 = time.perf_counter()
        error = papermill_once(notebook, folder, parameters, env, cwd, kernel, timeout, start_timeout)
        walls.append(round(time.perf_counter() - t0, 2))
        if error is None:
            break
    status = "ok" if error is None else "failed"
    rec = record(notebook, values, parameters, status, attempt, walls, error, run)
    report.write_json(folder / "point.json", rec)
    _event({"point": folder.name, "state": rec["status"], "wall_s": rec["wall_s"]})
    return rec


def record(notebook, values, parameters, status, attempts, walls, error, run="") -> dict:
    """The point.json record: parameters, status ("ok"/"failed"), attempts, wall time (s), error,
    and the id of the sweep run that wrote it."""
    return {"run": run, "notebook": str(notebook), "values": values, "parameters": parameters,
            "status": status, "attempts": attempts, "wall_s": round(sum(walls), 2),
            "attempt_wall_s": walls, "error": error, "host": socket.gethostname(),
            "finished": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}


# ----------------------------------------------------------------------------- the cluster

def jobqueue_cluster(kind: str, options: dict | None = None):
    """A dask-jobqueue SLURMCluster or PBSCluster (not yet scaled) whose jobs each run one point at
    a time (worker resource ``point=1``) with this checkout on PYTHONPATH.

    options: queue, cores, memory, walltime, account, job_extra_directives (None = take the dask
    config ``jobqueue.<kind>.*``, e.g. ~/.config/dask/jobqueue.yaml).
    """
    import dask
    import dask_jobqueue

    if kind not in JOBQUEUE:
        raise ValueError(f"unknown job queue {kind!r}: use one of {', '.join(JOBQUEUE)}")
    cls = {"slurm": dask_jobqueue.SLURMCluster, "pbs": dask_jobqueue.PBSCluster}[kind]
    kw = {k: v for k, v in (options or {}).items() if v not in (None, [], "")}
    conf = f"jobqueue.{kind}."
    kw["worker_extra_args"] = list(dask.config.get(conf + "worker-extra-args", None) or []) + [
        "--resources", "point=1"]
    kw["job_script_prologue"] = list(dask.config.get(conf + "job-script-prologue", None) or []) + [
        f"export PYTHONPATH={shlex.quote(str(ROOT))}${{PYTHONPATH:+:$PYTHONPATH}}"]
    if dask.config.get(conf + "processes", None) is None:
        kw.setdefault("processes", 1)
    try:
        return cls(**kw)
    except ValueError as e:
        raise ValueError(f"{e}\n(set them with --cores/--memory or in the dask config "
                         f"jobqueue.{kind}.cores / .memory)") from None


def default_workers() -> int:
    """Local workers by default: one per four cores (each point's trainer uses up to four threads)."""
    return max(1, (os.cpu_count() or 1) // 4)


def check_scheduler(scheduler: str) -> None:
    """Raise ValueError unless ``scheduler`` is local, slurm, pbs or an address (tcp://host:port)."""
    if scheduler not in ("local", *JOBQUEUE) and "://" not in scheduler \
            and not re.fullmatch(r"[\w.\-]+:\d+", scheduler):
        raise ValueError(f"unknown --scheduler {scheduler!r}: use local, slurm, pbs or a scheduler "
                         f"address such as tcp://host:8786")


@contextlib.contextmanager
def connect(scheduler: str = "local", workers: int | None = None, options: dict | None = None):
    """Yield ``(client, resources)`` for ``scheduler``: "local" (a LocalCluster of ``workers``
    single-threaded worker processes), an address (``tcp://host:8786``: a running scheduler and
    its workers) or "slurm"/"pbs" (dask-jobqueue, ``workers`` jobs). resources is what each task
    asks of its worker (None, or ``{"point": 1}`` on job queues)."""
    from distributed import Client, LocalCluster

    cluster, resources = None, None
    if workers is not None and workers < 1:
        raise ValueError(f"--workers must be >= 1, got {workers}")
    if scheduler == "local":
        cluster = LocalCluster(n_workers=workers or default_workers(), threads_per_worker=1,
                               processes=True, dashboard_address=None)
    elif scheduler in JOBQUEUE:
        cluster, resources = jobqueue_cluster(scheduler, options), {"point": 1}
        cluster.scale(workers or 1)
    else:
        check_scheduler(scheduler)
    client = Client(cluster if cluster is not None else scheduler)
    try:
        yield client, resources
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


# ----------------------------------------------------------------------------- driving the sweep

def _duration(s: float) -> str:
    """Seconds as ``42 s``, ``3 min 10 s`` or ``1 h 02 min``."""
    s = int(round(s))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"


def _progress(state: dict, slots: int) -> str:
    """One progress line: points done and failed of all, running, queued, estimated time left
    (mean wall time of the points finished so far, spread over the worker slots)."""
    total, done, failed = state["total"], state["done"], state["failed"]
    now = time.time()
    running = {k: t for k, t in state["running"].items() if k not in state["finished"]}
    queued = max(0, total - done - len(running))
    line = f"sweep: {done}/{total} done ({failed} failed), {len(running)} running, {queued} queued"
    walls = state["walls"]
    if walls and done < total:
        mean = sum(walls) / len(walls)
        left = mean * (queued + len(running)) - sum(min(now - t, mean) for t in running.values())
        line += f", ~{_duration(max(0.0, left) / max(1, slots))} left"
    elif done < total:
        line += ", time left: after the first point"
    return line


def _lost(point: dict, notebook, error: BaseException, run: str) -> dict:
    """Record a point whose task itself failed (e.g. its workers kept dying): point.json failed,
    and no temporary notebook left behind."""
    folder = point["folder"]
    folder.mkdir(parents=True, exist_ok=True)
    for tmp in folder.glob(".tmp-*"):
        tmp.unlink(missing_ok=True)
    rec = record(notebook, point["values"], point["parameters"], "failed", 0, [],
                 f"{type(error).__name__}: {error}", run)
    report.write_json(folder / "point.json", rec)
    return rec


def drive(client, todo: list[dict], notebook, env: dict, *, resources=None, kernel="greenloop",
          timeout=7200, retries=1, force=False, progress=True, every=30.0,
          start_timeout=START_TIMEOUT) -> dict[str, dict]:
    """Submit one ``run_point`` task per point in ``todo`` and wait for all of them, printing
    progress to stderr when a point starts or ends (and every ``every`` s). Returns {name: record}."""
    from distributed import wait

    run = uuid.uuid4().hex
    lock = threading.Lock()
    state = {"total": len(todo), "done": 0, "failed": 0, "running": {}, "finished": set(), "walls": [],
             "changed": True}

    def on_event(event):  # runs in the client's event loop: record only, print from this thread
        _, msg = event
        with lock:
            if msg.get("state") == "start" and msg["point"] not in state["finished"]:
                state["running"][msg["point"]] = msg.get("t", time.time())
                state["changed"] = True

    client.subscribe_topic(TOPIC, on_event)
    futures = {client.submit(run_point, str(notebook), str(p["folder"]), p["values"], p["parameters"],
                             env, str(ROOT), kernel, timeout, retries, force, run, start_timeout,
                             resources=resources, pure=False,
                             key=f"sweep-point-{p['name']}-{uuid.uuid4().hex[:8]}"): p for p in todo}
    records, pending, last = {}, set(futures), 0.0
    try:
        while pending:
            try:
                done, pending = wait(pending, timeout=1.0, return_when="FIRST_COMPLETED")
            except TimeoutError:
                done = set()
            for fut in done:  # drop each future at once: Dask would rerun a lost finished task
                point = futures.pop(fut)
                records[point["name"]] = _finish(fut, point, notebook, run, state, lock, progress)
                fut.release()
            with lock:
                due = state["changed"] or time.time() - last >= every
                state["changed"] = False
            if progress and due:
                line = _progress(state, _slots(client, resources))
                print(line, file=sys.stderr, flush=True)
                last = time.time()
    finally:
        client.unsubscribe_topic(TOPIC)
        client.cancel(list(pending))
    return records


def _finish(fut, point: dict, notebook, run: str, state: dict, lock, progress: bool) -> dict:
    """The record of a finished task (a task that itself failed is recorded as a failed point)."""
    try:
        rec = fut.result()
    except Exception as e:  # the task failed, not the notebook (e.g. its workers kept dying)
        rec = _lost(point, notebook, e, run)
    with lock:
        state["done"] += 1
        state["failed"] += rec["status"] != "ok"
        state["finished"].add(point["name"])
        state["running"].pop(point["name"], None)
        state["changed"] = True
        if rec["wall_s"]:
            state["walls"].append(rec["wall_s"])
    if progress:
        why = f" after {rec['attempts']} attempts: {rec['error']}" if rec["status"] != "ok" else ""
        print(f"sweep: {point['name']}: {rec['status']} in {_duration(rec['wall_s'])}{why}",
              file=sys.stderr, flush=True)
    return rec


def _slots(client, resources) -> int:
    """How many points can run at once: worker threads, or workers when each runs one point."""
    try:
        nthreads = client.nthreads()
    except Exception:  # the scheduler is gone: only the estimate suffers
        return 1
    return max(1, len(nthreads) if resources else sum(nthreads.values()))


# ----------------------------------------------------------------------------- the table and the figure

def _scalars(obj, prefix: str = "") -> dict:
    """The scalar leaves of a JSON object, keys joined by dots (lists are skipped)."""
    out = {}
    if isinstance(obj, dict):
        for k, v in obj.items():
            out.update(_scalars(v, f"{prefix}{k}."))
    elif obj is None or isinstance(obj, (bool, int, float, str)):
        out[prefix[:-1]] = obj
    return out


def sd_name(column: str, columns) -> str | None:
    """The spread column beside a mean column (``acc_mean_%`` -> ``acc_std_%``), if present."""
    for mean, sd in (("mean", "std"), ("mean", "sd"), ("avg", "std")):
        if mean in column and column.replace(mean, sd) in columns:
            return column.replace(mean, sd)
    return None


def metric_column(spec: str) -> str:
    """The table column a metric spec fills: COLUMN of ``FILE.csv[...]:COLUMN``, else the key."""
    m = _METRIC.match(spec)
    return m["col"] if m else spec


def read_metric(results: Path, spec: str) -> dict:
    """The numbers named by ``spec`` in one point's results folder ``<point>/<stem>/``.

    spec: ``KEY`` (a scalar of summary.json, nested keys joined by dots, e.g. ``derived.tau``), or
    ``FILE.csv:COLUMN`` (a one-row CSV), or ``FILE.csv[KEY=VALUE]:COLUMN`` (the row where KEY equals
    the YAML value VALUE). Returns {COLUMN: value} plus its spread column (see ``sd_name``).
    """
    m = _METRIC.match(spec)
    if not m:
        path = results / "summary.json"
        scalars = _scalars(json.loads(path.read_text())) if path.is_file() else {}
        if spec not in scalars:
            raise ValueError(f"metric {spec!r} is not a scalar of {path}: its scalars are "
                             f"{', '.join(scalars) or 'none'}; name a CSV column as FILE.csv:COLUMN")
        sd = sd_name(spec, scalars)
        return {spec: scalars[spec], **({sd: scalars[sd]} if sd else {})}
    path = results / m["file"]
    if not path.is_file():
        raise FileNotFoundError(f"metric {spec!r}: {path} not found (the notebook writes "
                                f"{', '.join(sorted(p.name for p in results.glob('*.csv'))) or 'no CSV'})")
    t = pd.read_csv(path)
    if m["key"]:
        if m["key"] not in t.columns:
            raise ValueError(f"metric {spec!r}: {path.name} has no column {m['key']!r}")
        t = t[t[m["key"]] == yaml.safe_load(m["val"])]
    if len(t) != 1:
        raise ValueError(f"metric {spec!r}: {len(t)} rows of {path.name} match; pick one row with "
                         f"{m['file']}[COLUMN=VALUE]:{m['col']}")
    if m["col"] not in t.columns:
        raise ValueError(f"metric {spec!r}: {path.name} has no column {m['col']!r}; its columns are "
                         f"{', '.join(t.columns)}")
    row = t.iloc[0]
    sd = sd_name(m["col"], t.columns)
    return {m["col"]: row[m["col"]].item(), **({sd: row[sd].item()} if sd else {})}


def collect(points: list[dict], notebook, metrics=()) -> "pd.DataFrame":
    """One row per point: its grid values (non-scalars as YAML flow text), status, attempts, wall
    time (s), error, the scalars of its ``<stem>/summary.json`` and the ``metrics`` (see
    ``read_metric``; read for points that finished ok)."""
    stem = Path(notebook).stem
    rows = []
    for p in points:
        row = {k: (v if v is None or isinstance(v, (bool, int, float, str)) else flow(v))
               for k, v in p["values"].items()}
        try:
            rec = json.loads((p["folder"] / "point.json").read_text())
        except (OSError, ValueError):
            rec = {"status": "not run", "attempts": 0, "wall_s": None, "error": None}
        row.update(status=rec["status"], attempts=rec["attempts"], wall_s=rec["wall_s"],
                   error=(rec["error"] or "").splitlines()[0][:300] if rec["error"] else "")
        if rec["status"] == "ok":
            results = p["folder"] / stem
            summary = results / "summary.json"
            if summary.is_file():
                row.update({k: v for k, v in _scalars(json.loads(summary.read_text())).items()
                            if k not in row})
            for spec in metrics:
                row.update(read_metric(results, spec))
        rows.append(row)
    return pd.DataFrame(rows)


def _numeric(v):
    """A swept value as a number for the x axis: ``40`` or ``[40]`` -> 40.0; else None."""
    if isinstance(v, list) and len(v) == 1:
        v = v[0]
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else None


def figure(points: list[dict], table, metric: str, x: str | None = None, title: str = ""):
    """The swept quantity ``x`` (default: the first grid name with numeric values) against column
    ``metric`` of ``table``, one line per setting of the other grid names, error bars from the
    metric's spread column. Failed points are left out (the title counts them)."""
    from matplotlib.figure import Figure

    names = list(points[0]["values"])
    if x is None:
        x = next((n for n in names if all(_numeric(p["values"][n]) is not None for p in points)), names[0])
    if x not in names:
        raise ValueError(f"--x {x!r} is not swept: choose one of {', '.join(names)}")
    numeric = all(_numeric(p["values"][x]) is not None for p in points)
    labels = list(dict.fromkeys(flow(p["values"][x]) for p in points))
    sd = sd_name(metric, table.columns)
    fig = Figure(figsize=(6.4, 4.2))
    ax = fig.subplots()
    series: dict[str, list] = {}
    for p, (_, row) in zip(points, table.iterrows()):
        if row["status"] != "ok" or metric not in row or pd.isna(row[metric]):
            continue
        other = ", ".join(f"{k}={flow(v)}" for k, v in p["values"].items() if k != x)
        xv = _numeric(p["values"][x]) if numeric else labels.index(flow(p["values"][x]))
        series.setdefault(other, []).append((xv, row[metric], row[sd] if sd else None))
    for other, pts in series.items():
        pts.sort(key=lambda t: t[0])
        xs, ys, es = zip(*pts)
        ax.errorbar(xs, ys, yerr=es if sd else None, marker="o", capsize=4, label=other or None)
    if not numeric:
        ax.set_xticks(range(len(labels)), labels, rotation=20)
    elif len(labels) <= 12:
        ax.set_xticks(sorted({_numeric(p["values"][x]) for p in points}))
    ax.set_xlabel(x)
    ax.set_ylabel(metric + (f" (error bars: {sd})" if sd else ""))
    failed = int((table["status"] != "ok").sum())
    ax.set_title(f"{title}{': ' if title else ''}{len(table)} points"
                 + (f", {failed} failed (not shown)" if failed else ""))
    if any(series):
        ax.legend(fontsize="small")
    ax.grid(alpha=0.3)
    return fig


def write_outputs(points, table, out: Path, notebook, metric: str | None, x: str | None = None) -> Path:
    """``<out>/sweep.csv``, ``<out>/sweep.md`` and (when a metric is numeric somewhere)
    ``<out>/sweep.png``. Returns the .md path."""
    if metric is None:  # default: the first numeric summary scalar, else the wall time
        skip = set(points[0]["values"]) | {"status", "attempts", "wall_s", "error"}
        metric = next((c for c in table.columns if c not in skip
                       and pd.api.types.is_numeric_dtype(table[c]) and table[c].notna().any()), "wall_s")
    failed = table[table.status != "ok"]
    note = (f"Notebook `{Path(notebook).name}`, one papermill run per point; parameters injected on top "
            f"of the notebook's defaults are in each point's `point.json`. Figure: `sweep.png` "
            f"({metric}).")
    if len(failed):
        note += f" {len(failed)} point(s) failed; their error is in the `error` column and point.json."
    md = report.write_table(table, Path(out) / "sweep", title=f"Sweep of {Path(notebook).stem}", note=note)
    png = Path(out) / "sweep.png"
    if metric in table.columns and pd.api.types.is_numeric_dtype(table[metric]):
        report.save_figure(figure(points, table, metric, x, title=Path(notebook).stem), png)
    else:  # nothing to plot (every point failed): no figure of an earlier run left beside the table
        png.unlink(missing_ok=True)
    return md


# ----------------------------------------------------------------------------- the whole sweep

def run_sweep(notebook, grid: dict, out, *, base: dict | None = None, dataset=DEFAULT_DATASET,
              scheduler: str = "local", workers: int | None = None, cache=None, metrics=(),
              x: str | None = None, force: bool = False, timeout: int = 7200, kernel: str = "greenloop",
              retries: int = 1, cluster_options: dict | None = None, progress: bool = True,
              start_timeout: int = START_TIMEOUT):
    """Run every point of ``grid`` (see ``parse_grid``) over ``notebook`` into ``out`` on Dask,
    skipping complete points unless ``force``, then write sweep.csv/.md/.png.

    base: parameters for every point (e.g. read from params/tiny.yaml), only the names the notebook
    declares (``plan``); the grid's values win.
    metrics: ``read_metric`` specs; the first is the figure's y axis.
    timeout: seconds per cell; start_timeout: seconds for each point's kernel to answer.
    Returns the table (pandas DataFrame, one row per point).
    """
    notebook = Path(notebook).resolve()
    if not notebook.is_file():
        raise FileNotFoundError(f"notebook {notebook} not found: pass a notebook path such as "
                                f"notebooks/01_spot_grouping.ipynb")
    check_grid(grid, notebook_parameters(notebook), notebook)
    check_scheduler(scheduler)
    if x is not None and x not in grid:
        raise ValueError(f"--x {x!r} is not swept: choose one of {', '.join(grid)}")
    out = Path(out).resolve()
    points = plan(grid, out, base, dataset, notebook)
    todo = [p for p in points if force or not is_complete(p, notebook)]
    if progress:
        print(f"sweep: {len(points)} point{'s' * (len(points) != 1)} of {notebook.name} into {out}; "
              f"{len(points) - len(todo)} complete already, {len(todo)} to run", file=sys.stderr, flush=True)
    if todo:
        out.mkdir(parents=True, exist_ok=True)
        env = point_env(cache)
        with connect(scheduler, workers, cluster_options) as (client, resources):
            drive(client, todo, notebook, env, resources=resources, kernel=kernel, timeout=timeout,
                  retries=retries, force=force, progress=progress, start_timeout=start_timeout)
    table = collect(points, notebook, metrics)
    md = write_outputs(points, table, out, notebook, metric_column(metrics[0]) if metrics else None, x)
    if progress:
        failed = int((table.status != "ok").sum())
        print(f"sweep: {len(table) - failed} ok, {failed} failed; table {md}", file=sys.stderr, flush=True)
    return table
