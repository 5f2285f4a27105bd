import json
import os

import pandas as pd
import pytest

from conftest import execute_notebook
from greenloop import report
from greenloop.cli import main as cli_main
from greenloop.study import report as study_report


def test_tables_and_assembly(tmp_path):
    df = report.paper_vs_run([("accuracy (%)", 98, 91.5), ("spots", 38, 38, "arithmetic")])
    assert list(df.columns) == ["quantity", "paper", "this run", "note"]
    report.write_table(df, tmp_path / "01_x" / "paper_vs_run", title="T")
    report.write_json(tmp_path / "01_x" / "manifest.json", {"date": "D", "cpu": "C", "dataset": "S"})
    (tmp_path / "models").mkdir()
    out = study_report.assemble_tables(tmp_path)
    text = out.read_text()
    assert "## 01_x" in text and "| accuracy (%) |" in text and "91.5" in text and "models" not in text
    assert pd.read_csv(tmp_path / "01_x" / "paper_vs_run.csv").shape == (2, 4)
    assert not list(tmp_path.rglob(".tmp-*"))


def test_command_line_assembles_and_refuses_a_missing_folder(tmp_path, capsys):
    report.write_table(report.paper_vs_run([("spots", 38, 38)]), tmp_path / "01_x" / "paper_vs_run", title="T")
    assert cli_main(["tables", str(tmp_path)]) == 0
    assert capsys.readouterr().out.strip() == str(tmp_path / "tables.md")
    assert "## 01_x" in (tmp_path / "tables.md").read_text()
    with pytest.raises(SystemExit) as e:
        cli_main(["tables", str(tmp_path / "nope")])
    assert e.value.code == 2 and "no such results folder" in capsys.readouterr().err


def test_manifest_records_machine_and_versions(tmp_path):
    report.manifest(tmp_path, {"epochs": 3}, dataset=tmp_path / "missing")
    m = json.loads((tmp_path / "manifest.json").read_text())
    assert m["parameters"] == {"epochs": 3} and "numpy" in m["versions"] and m["cpu"]
    assert m["dataset_fingerprint"].startswith("unavailable")


def test_parameters_reads_the_cell_before_papermills_injection():
    """Names from the cell run just before papermill's injected one (an earlier cell and a name papermill
    injected undeclared are left out), values from the namespace; a derived value is added, and one
    named as a parameter replaces it."""
    ns = {"In": ["", "import json", 'a = 1  # c\nb: int = 2\nc = d = [3]\n"""a docstring"""',
                 f"{report.INJECTED}\na = 5\nzz = 0", "x = 9"], "a": 5, "b": 2, "c": [3], "d": [3], "zz": 0, "x": 9}
    assert report.parameters(ns) == {"a": 5, "b": 2, "c": [3], "d": [3]}
    assert report.parameters(ns, b=7, used=1) == {"a": 5, "b": 7, "c": [3], "d": [3], "used": 1}
    ns["In"] += ["a = 6", f"{report.INJECTED}\nb = 1"]       # papermill ran again in the same kernel: the last injection
    assert report.parameters(ns) == {"a": 5}
    # nothing injected: the first cell the kernel ran, which must hold only assignments
    assert report.parameters({"In": ["", "a = 1", "x = a + 1"], "a": 1, "x": 2}) == {"a": 1}
    with pytest.raises(ValueError, match="not a parameters cell"):
        report.parameters({"In": ["", "import json\na = 1"], "a": 1})
    with pytest.raises(ValueError, match="no cell tagged 'parameters'"):
        report.parameters({"In": ["", f"{report.INJECTED}\na = 1"], "a": 1})
    with pytest.raises(ValueError, match="input history"):
        report.parameters({"a": 1})
    with pytest.raises(ValueError, match=r"\['b'\].*globals\(\)"):
        report.parameters({"In": ["", "a = 1\nb = 2"], "a": 1})


def test_injected_marker_is_papermills():
    from papermill.translators import PythonTranslator
    assert PythonTranslator.codify({"epochs": 2}).splitlines()[0] == report.INJECTED


def _tiny_notebook(path, lead=None):
    """A notebook as the study writes them (a parameters cell, then a call into greenloop), in tmp;
    lead: a code cell before the parameters cell."""
    import nbformat
    params = nbformat.v4.new_code_cell('out = "res"                # where the manifest goes\nepochs = 200\n'
                                       'seeds = [0, 1, 2]\nweights = None\ntau_list = list(range(40, 50, 5))')
    params.metadata["tags"] = ["parameters"]
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell("# a tiny notebook"),
                                         *([nbformat.v4.new_code_cell(lead)] if lead else []), params,
                                         nbformat.v4.new_code_cell("from greenloop import report\n"
                                                                   "report.manifest(out, report.parameters(globals(), "
                                                                   "seeds_used=seeds[:1]));")])
    nb.metadata["kernelspec"] = {"name": "greenloop", "display_name": "Python (greenloop)", "language": "python"}
    nbformat.write(nb, path)
    return path


@pytest.mark.parametrize("injected", [{"epochs": 2}, None], ids=["injected", "defaults"])
def test_manifest_of_a_papermill_run_holds_every_parameter(tmp_path, monkeypatch, injected):
    """papermill runs a notebook in tmp (its folder the kernel's working directory, not the checkout):
    the manifest holds every parameter of its cell, the injected value winning, and the derived value
    the notebook gave; where nothing is injected (the parameters cell first), the cell's defaults."""
    monkeypatch.setenv("PYTHONPATH", str(report.ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    nb = _tiny_notebook(tmp_path / "tiny.ipynb", lead="import json" if injected else None)
    execute_notebook(nb, tmp_path / "out.ipynb", parameters=injected, cwd=str(tmp_path))
    m = json.loads((tmp_path / "res" / "manifest.json").read_text())
    assert m["parameters"] == {"out": "res", "epochs": 2 if injected else 200, "seeds": [0, 1, 2], "weights": None,
                               "tau_list": [40, 45], "seeds_used": [0]}


def test_cross_dataset_table_puts_datasets_side_by_side(tmp_path):
    for name, ap in (("synthetic", 40.0), ("nordland", 12.5)):
        folder = tmp_path / name / "07_feature_baselines"
        report.write_json(folder / "summary.json", {"table": [
            {"label": "pixels (none)", "AP_%": ap, "R@100P_%": 1.0, "R@1_%": 50.0}]})
        report.write_json(folder / "manifest.json", {"dataset": f"data/{name}"})
        report.write_json(tmp_path / name / "01_spot_grouping" / "summary.json", {"table1": [
            {"frames_per_spot": 60, "acc_mean_%": 93.0, "acc_std_%": 2.0, "seeds": 5}]})
    report.write_json(tmp_path / "nordland" / "12_revisit_protocol" / "summary.json", {
        "per_seed": [{"split": "random", "seed": 0, "in_traversal_test_acc_%": 99.0, "revisit_acc_%": 20.0},
                     {"split": "random", "seed": 1, "in_traversal_test_acc_%": 97.0, "revisit_acc_%": 30.0}],
        "dictionary": [{"tau_rule": "chosen", "tau": 65, "precision": 0.5, "recall": 0.25}]})
    report.write_json(tmp_path / "nordland" / "13_leaderboard" / "summary.json", {"leaderboard": [
        {"method": "greenloop-seq", "mode": "loop closure", "knobs": "pixels, whitening none, seq_len 10",
         "queries": 203, "revisit_queries": 180, "R@1_%": 87.0, "AUC-PR_%": 61.5, "R@100P_%": 20.0},
        {"method": "greenloop-seq", "mode": "place recognition", "knobs": "pixels, whitening none, seq_len 10",
         "R@1_%": 90.0, "AUC-PR_%": 70.0, "R@100P_%": 30.0},
        {"method": "greenloop-seq-fast", "mode": "loop closure", "knobs": "pixels", "R@1_%": float("nan"),
         "AUC-PR_%": float("nan"), "R@100P_%": float("nan")}]})
    t = study_report.cross_dataset([tmp_path / "synthetic", tmp_path / "nordland", tmp_path / "absent"])
    seq = t[t.method.str.startswith("greenloop-seq")]        # a row that was not run (NaN) is left out
    assert dict(zip(seq.metric, seq.nordland)) == {"R@1_%": "87.0 (pixels)", "AUC-PR_%": "61.5 (pixels)",
                                                   "R@100P_%": "20.0 (pixels)", "queries (revisit queries)": "203 (180)"}
    assert len(seq) == 4                     # loop closure only; the counts where the summary has them
    assert list(t.columns) == ["method", "metric", "synthetic", "nordland"]
    ap = t[(t.method == "pixels (none), cosine") & (t.metric == "AP_%")].iloc[0]
    assert (ap.synthetic, ap.nordland) == (40.0, 12.5)
    rev = t[t.method.str.contains("revisit frames")].iloc[0]
    assert rev.nordland == "25.0 ± 7.1 (2 seeds)" and rev.synthetic == ""
    out = study_report.write_cross_dataset([tmp_path / "synthetic", tmp_path / "nordland"], tmp_path / "datasets.md")
    assert "| pixels (none), cosine" in out.read_text()
    with pytest.raises(FileNotFoundError, match="make all"):
        study_report.cross_dataset([tmp_path / "absent"])


def test_coverage_status_comes_from_the_outputs(tmp_path):
    from greenloop.study import coverage
    a, b = tmp_path / "a", tmp_path / "b"
    for folder, name in ((a, "synthetic"), (b, "real")):
        report.write_json(folder / "00_dataset" / "manifest.json", {"dataset": f"data/{name}"})
    (a / "07_feature_baselines").mkdir()
    (a / "07_feature_baselines" / "table2.csv").write_text("x\n")
    t = coverage.coverage([a, b]).set_index(["paper", "item"])
    assert len(t) == len(coverage.ITEMS) and t.index.is_unique
    row = t.loc[(coverage.QI, "Table 2")]
    assert row.status == "protocol partly ran" and row.datasets == "synthetic"       # declared, and found in a only
    missing = t.loc[(coverage.QI, "Table 6")]                             # declared reproduced, no file
    assert missing.status == "not run" and "11_lsh_matching/table6.csv" in missing.note
    assert t.loc[(coverage.ZHANG, "Table I")].status == "not reproduced"  # no output: declared status kept
    assert set(t.status) <= {"protocol ran", "protocol partly ran", "not reproduced", "not an experiment", "not run"}
    assert (t.status != "not an experiment").sum() > 20
    # an RGB-D table whose every row says skipped (no depth) is no result; one run row is
    layers = "10_siamese_rgbd/table2_mid_level_layers.csv"
    for folder, rows in ((a, "conv1,0.74,0.61,\nconv2,0.81,skipped,no depth\n"),
                         (b, "conv1,0.74,skipped,no depth\nconv2,0.81,skipped,no depth\n")):
        (folder / layers).parent.mkdir()
        (folder / layers).write_text("quantity,paper,this run,note\n" + rows)
    (b / "10_siamese_rgbd" / "fusions.csv").write_text("descriptor,status\nearly,skipped: the dataset has no depth/ folder\n")
    t = coverage.coverage([a, b]).set_index(["paper", "item"])
    assert t.loc[(coverage.XU, "Table 2")].datasets == "synthetic"
    assert t.loc[(coverage.XU, "Fig. 5, Fig. 6")].status == "not run"
    assert coverage.ran(a / layers) and not coverage.ran(b / layers) and not coverage.ran(b / "absent.csv")


def test_committed_coverage_table_is_the_generated_one():
    """results/coverage.md is what greenloop.study.coverage reads from the committed results."""
    from pathlib import Path
    from greenloop.study import coverage
    root = Path(__file__).resolve().parents[1]
    dirs = [root / "results"] + sorted(p.parent for p in (root / "results").glob("*/07_feature_baselines")
                                       if p.parent.name != "quick")
    committed = pd.read_csv(root / "results" / "coverage.csv", dtype=str, keep_default_na=False)
    fresh = study_report.coverage_with_claims(dirs).astype(str)
    assert committed.equals(fresh), "results/coverage.md is stale: make readme"
