"""greenloop.study.sweep: grids and point names, a 2-point sweep of notebook 01 on a 2-worker Dask
LocalCluster against the same points run one after another, and the faults: a point that raises,
a point that raises once, a rerun after an interruption, a worker killed mid-point.

Every fault is planted by the notebook itself (a parameter, a marker file), never by a clock: each
kernel gets KERNEL_START_S to answer and Dask's connections generous timeouts, so a slow machine
cannot turn a kernel start into a failed attempt (papermill's default 60 s once made a point take
2 attempts on a loaded 2-core machine)."""
import json
import os
from pathlib import Path

import nbformat
import pandas as pd
import pytest
import yaml

from conftest import KERNEL_START_S, execute_notebook
from greenloop.study import sweep

ROOT = Path(__file__).resolve().parents[1]
NB01 = ROOT / "notebooks" / "01_spot_grouping.ipynb"
TINY = yaml.safe_load((ROOT / "params" / "tiny.yaml").read_text())


# --------------------------------------------------------------------------- grids and names

def test_grid_values_are_yaml_scalars():
    g = sweep.parse_grid(["epochs=20,50", "lr=0.5", "seeds=[0,1],[2]", "weights=null,imagenet"])
    assert g == {"epochs": [20, 50], "lr": [0.5], "seeds": [[0, 1], [2]], "weights": [None, "imagenet"]}
    assert list(g) == ["epochs", "lr", "seeds", "weights"]
    for bad in (["epochs"], ["epochs="], ["1x=2"], ["epochs=1", "epochs=2"], ["a=[1"], ["x=1,2,1"], []):
        with pytest.raises(ValueError):
            sweep.parse_grid(bad)


def test_point_names_are_filesystem_safe_deterministic_and_distinct():
    assert sweep.point_name({"frames_per_spot_list": [40]}) == "frames_per_spot_list=[40]"
    assert sweep.point_name({"epochs": 50, "weights": None, "lr": 0.5}) == "epochs=50__weights=null__lr=0.5"
    assert sweep.point_name({"seeds": [0, 1]}) == "seeds=[0,1]"
    odd = [{"dataset": "data/my set"}, {"dataset": "data/my-set"}, {"dataset": "data/my_set"}, {"a": "1"},
           {"a": 1}]
    names = [sweep.point_name(v) for v in odd]
    assert len(set(names)) == len(names)
    assert all("/" not in n and " " not in n and "'" not in n for n in names)
    assert names == [sweep.point_name(v) for v in odd]


def test_grid_names_and_shapes_are_checked_against_the_notebook():
    params = sweep.notebook_parameters(NB01)
    assert {"seeds", "seeds_per_grouping", "frames_per_spot_list", "epochs"} <= set(params)
    sweep.check_grid({"epochs": [1, 2], "frames_per_spot_list": [[40]], "dataset": ["x"]}, params, NB01)
    with pytest.raises(ValueError, match="no parameter 'epoch'"):
        sweep.check_grid({"epoch": [1]}, params, NB01)
    with pytest.raises(ValueError, match=r"frames_per_spot_list=\[40\],\[50\]"):
        sweep.check_grid({"frames_per_spot_list": [40, 50]}, params, NB01)
    with pytest.raises(ValueError, match="results_dir"):
        sweep.check_grid({"results_dir": ["a"]}, params, NB01)
    for ok in ("local", "slurm", "pbs", "tcp://10.0.0.1:8786", "node7:8786"):
        sweep.check_scheduler(ok)
    with pytest.raises(ValueError, match="unknown --scheduler"):
        sweep.check_scheduler("slrum")


def test_metric_specs_read_summary_scalars_and_csv_cells(tmp_path):
    (tmp_path / "summary.json").write_text(json.dumps({"derived": {"tau": 70}, "ap_mean": 0.5, "ap_std": 0.1,
                                                       "rows": [1, 2]}))
    pd.DataFrame({"L": [50, 60], "acc_mean_%": [90.0, 95.0], "acc_std_%": [2.0, 1.0]}).to_csv(
        tmp_path / "t.csv", index=False)
    assert sweep.read_metric(tmp_path, "derived.tau") == {"derived.tau": 70}
    assert sweep.read_metric(tmp_path, "ap_mean") == {"ap_mean": 0.5, "ap_std": 0.1}
    assert sweep.read_metric(tmp_path, "t.csv[L=60]:acc_mean_%") == {"acc_mean_%": 95.0, "acc_std_%": 1.0}
    with pytest.raises(ValueError, match="2 rows"):
        sweep.read_metric(tmp_path, "t.csv:acc_mean_%")
    with pytest.raises(ValueError, match="no column"):
        sweep.read_metric(tmp_path, "t.csv[L=60]:acc")
    with pytest.raises(ValueError, match="not a scalar"):
        sweep.read_metric(tmp_path, "rows")


def test_slurm_jobs_run_one_point_each_with_this_checkout():
    cluster = sweep.jobqueue_cluster("slurm", dict(queue="gpu", cores=8, memory="16GB", walltime="01:00:00",
                                                   account=None, job_extra_directives=None))
    try:
        script = cluster.job_script()
    finally:
        cluster.close()
    assert "#SBATCH -p gpu" in script and "#SBATCH --cpus-per-task=8" in script
    assert "--resources point=1" in script and f"export PYTHONPATH={ROOT}" in script
    with pytest.raises(ValueError, match="unknown job queue"):
        sweep.jobqueue_cluster("condor")


# --------------------------------------------------------------------------- a real notebook on 2 workers

def _plain_loop(points, base, dataset, folder):
    """The points one after another, each a plain papermill run (no Dask), into folder/<point>/."""
    for values in points:
        out = folder / sweep.point_name(values)
        out.mkdir(parents=True)
        execute_notebook(NB01, out / "nb.ipynb", cwd=str(ROOT),
                         parameters=dict(base, **values, dataset=str(dataset), results_dir=str(out)))


@pytest.mark.notebook
def test_two_worker_sweep_matches_the_points_run_one_after_another(tiny_sequence, tmp_path, monkeypatch):
    from concurrent.futures import ThreadPoolExecutor

    grid = {"frames_per_spot_list": [[40], [50]], "epochs": [1]}            # 2 points, each on a worker
    points = [{"frames_per_spot_list": L, "epochs": e} for L in ([40], [50]) for e in (1,)]
    base = dict(TINY, seeds=[0], seeds_per_grouping=[0])
    out, loop = tmp_path / "sweep", tmp_path / "loop"
    # the plain run has a model cache of its own and runs beside the sweep (two cores, both busy); it
    # repeats the second point only (the first point's table is checked against the sweep's row)
    monkeypatch.setenv("PYTHONPATH", str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    monkeypatch.setenv("GREENLOOP_CACHE", str(tmp_path / "cache-loop"))
    with ThreadPoolExecutor(1) as pool:
        looped = pool.submit(_plain_loop, points[1:], base, tiny_sequence, loop)
        table = sweep.run_sweep(NB01, grid, out, base=base, dataset=tiny_sequence, workers=2,
                                cache=tmp_path / "cache-sweep", metrics=["table1.csv:acc_mean_%"],
                                progress=False, start_timeout=KERNEL_START_S)
        looped.result()
    assert (table.status == "ok").all() and len(table) == 2
    assert table.frames_per_spot_list.tolist() == ["[40]", "[50]"]
    assert table.epochs.tolist() == [1, 1]
    for k, (values, (_, row)) in enumerate(zip(points, table.iterrows())):
        name = sweep.point_name(values)
        theirs = pd.read_csv(out / name / "01_spot_grouping" / "table1.csv")
        if k:
            pd.testing.assert_frame_equal(theirs, pd.read_csv(loop / name / "01_spot_grouping" / "table1.csv"))
        assert theirs.frames_per_spot.tolist() == values["frames_per_spot_list"]
        assert (row["acc_mean_%"], row["acc_std_%"]) == (theirs["acc_mean_%"][0], theirs["acc_std_%"][0])
    on_disk = pd.read_csv(out / "sweep.csv")
    assert on_disk["acc_mean_%"].tolist() == table["acc_mean_%"].tolist()
    assert (out / "sweep.md").read_text().count("\n| [") == 2 and (out / "sweep.png").stat().st_size > 0
    # one shared cache: per point one Table 1 model and 01's three leakage controls per control seed
    assert len(list((tmp_path / "cache-sweep").glob("*/model.keras"))) == 2 * (1 + 3 * len(TINY["control_seeds"]))
    for p in sweep.plan(grid, out, base, tiny_sequence):
        rec = json.loads((p["folder"] / "point.json").read_text())
        assert rec["status"] == "ok" and rec["parameters"]["results_dir"] == str(p["folder"])
        assert (p["folder"] / "01_spot_grouping.ipynb").is_file()
    assert not list(out.rglob(".tmp*"))


# --------------------------------------------------------------------------- faults, on a tiny notebook

TINY_NB = '''\
import json, os, signal, time
from pathlib import Path
with open(Path(counter) / f"{x}.txt", "a") as fh:
    fh.write("run\\n")
if x == fail_at:
    raise ValueError(f"x is {x}")
once = Path(counter) / f"failed-once-{x}"
if x == fail_once_at and not once.exists():
    once.write_text("once")
    raise ValueError(f"x is {x}, the first time")
flag = Path(counter) / "killed"
if x == kill_at and not flag.exists():
    flag.write_text("once")
    os.kill(os.getppid(), signal.SIGKILL)   # the kernel's parent: the Dask worker running this point
    time.sleep(60)
out = Path(results_dir) / "tiny"
out.mkdir(parents=True, exist_ok=True)
(out / "summary.json").write_text(json.dumps({"y_mean": x * x, "y_std": 0.5, "dataset": dataset}))
'''


@pytest.fixture(scope="module", autouse=True)
def patient_dask():
    """Dask's connect and comm timeouts far above any start-up on a loaded machine (hang guards:
    a worker or scheduler slow to answer is not lost); the workers a LocalCluster starts inherit them."""
    import dask

    with dask.config.set({"distributed.comm.timeouts.connect": f"{KERNEL_START_S}s",
                          "distributed.comm.timeouts.tcp": f"{KERNEL_START_S}s"}):
        yield


@pytest.fixture(scope="module")
def tiny_nb(tmp_path_factory):
    """A two-cell notebook: counts its runs in counter/<x>.txt, raises at x == fail_at, raises on its
    first run only at x == fail_once_at (a marker file), kills its Dask worker once at x == kill_at,
    else writes tiny/summary.json."""
    nb = nbformat.v4.new_notebook()
    params = nbformat.v4.new_code_cell('x = 0\nfail_at = -1\nfail_once_at = -1\nkill_at = -1\ncounter = ""\n'
                                       'dataset = ""\nresults_dir = "results"')
    params.metadata["tags"] = ["parameters"]
    nb.cells = [params, nbformat.v4.new_code_cell(TINY_NB)]
    nb.metadata["kernelspec"] = {"name": "greenloop", "display_name": "greenloop", "language": "python"}
    path = tmp_path_factory.mktemp("nb") / "tiny.ipynb"
    nbformat.write(nb, path)
    return path


@pytest.fixture(scope="module")
def cluster():
    """Two single-threaded worker processes, reached by address as a running scheduler would be."""
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as c:
        yield c


def _runs(counter: Path) -> dict:
    return {int(p.stem): len(p.read_text().split()) for p in counter.glob("*.txt")}


@pytest.fixture(scope="module")
def failed_sweep(tiny_nb, cluster, tiny_sequence, tmp_path_factory):
    """Where the x = 1..4 sweep with x = 2 raising and x = 3 raising once runs (by address), and its
    arguments."""
    root = tmp_path_factory.mktemp("faults")
    (root / "counter").mkdir()
    kw = dict(base={"counter": str(root / "counter"), "fail_at": 2, "fail_once_at": 3}, dataset=tiny_sequence,
              scheduler=cluster.scheduler_address, metrics=["y_mean"], start_timeout=KERNEL_START_S)
    return root, kw


def test_a_failing_point_is_retried_once_and_recorded_while_the_others_finish(failed_sweep, tiny_nb, capfd):
    root, kw = failed_sweep
    table = sweep.run_sweep(tiny_nb, {"x": [1, 2, 3, 4]}, root / "out", **kw)
    err = capfd.readouterr().err
    # x = 2 retried once, then given up; x = 3 failed once, then passed on its retry
    assert _runs(root / "counter") == {1: 1, 2: 2, 3: 2, 4: 1}
    assert table.status.tolist() == ["ok", "failed", "ok", "ok"]
    assert table.attempts.tolist() == [1, 2, 2, 1]
    assert table.y_mean.dropna().tolist() == [1, 9, 16] and table.y_std.dropna().tolist() == [0.5] * 3
    rec = json.loads((root / "out" / "x=2" / "point.json").read_text())
    assert rec["status"] == "failed" and rec["error"].startswith("ValueError: x is 2")
    assert len(rec["attempt_wall_s"]) == 2
    again = json.loads((root / "out" / "x=3" / "point.json").read_text())
    assert again["status"] == "ok" and again["error"] is None and len(again["attempt_wall_s"]) == 2
    assert not (root / "out" / "x=3" / "tiny.failed.ipynb").exists()      # the retry cleared the failed run
    assert "ValueError: x is 2" in pd.read_csv(root / "out" / "sweep.csv").error[1]
    assert (root / "out" / "x=2" / "tiny.failed.ipynb").is_file()
    assert not (root / "out" / "x=2" / "tiny.ipynb").exists() and not list((root / "out").rglob(".tmp*"))
    for x in (1, 3, 4):
        s = json.loads((root / "out" / f"x={x}" / "tiny" / "summary.json").read_text())
        assert s == {"y_mean": x * x, "y_std": 0.5, "dataset": str(Path(kw["dataset"]).resolve())}
    assert "sweep: 4/4 done (1 failed)" in err and "running" in err and "left" in err
    assert "failed in" in err and "after 2 attempts: ValueError: x is 2" in err


def test_a_rerun_skips_finished_points(failed_sweep, tiny_nb):
    root, kw = failed_sweep
    out = root / "out"
    stamps = {x: (out / f"x={x}" / "point.json").stat().st_mtime_ns for x in (1, 3, 4)}
    table = sweep.run_sweep(tiny_nb, {"x": [1, 2, 3, 4]}, out, progress=False, **kw)
    assert _runs(root / "counter") == {1: 1, 2: 4, 3: 2, 4: 1}         # only the failed point ran again
    assert {x: (out / f"x={x}" / "point.json").stat().st_mtime_ns for x in (1, 3, 4)} == stamps
    assert table.status.tolist() == ["ok", "failed", "ok", "ok"]
    # other base parameters make other points: every one runs again
    kw2 = dict(kw, base=dict(kw["base"], fail_at=-1))
    table = sweep.run_sweep(tiny_nb, {"x": [1, 3]}, out, progress=False, **kw2)
    assert _runs(root / "counter") == {1: 2, 2: 4, 3: 3, 4: 1} and (table.status == "ok").all()


def test_a_worker_killed_mid_point_loses_no_finished_point(tiny_nb, cluster, tiny_sequence, tmp_path):
    (tmp_path / "counter").mkdir()
    base = {"counter": str(tmp_path / "counter"), "kill_at": 3}
    table = sweep.run_sweep(tiny_nb, {"x": [1, 2, 3, 4]}, tmp_path / "out", base=base, dataset=tiny_sequence,
                            scheduler=cluster.scheduler_address, metrics=["y_mean"], progress=False,
                            start_timeout=KERNEL_START_S)
    assert (tmp_path / "counter" / "killed").is_file()
    assert (table.status == "ok").all() and table.y_mean.tolist() == [1, 4, 9, 16]
    assert _runs(tmp_path / "counter") == {1: 1, 2: 1, 3: 2, 4: 1}     # only the killed point ran twice
    assert not list((tmp_path / "out").rglob(".tmp*"))
