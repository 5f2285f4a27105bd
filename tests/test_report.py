import json

import pandas as pd

from greenloop import report


def test_tables_and_assembly(tmp_path):
    df = report.paper_vs_run([("accuracy (%)", 98, 91.5), ("spots", 38, 38, "arithmetic")])
    assert list(df.columns) == ["quantity", "paper", "this run", "note"]
    report.write_table(df, tmp_path / "01_x" / "paper_vs_run", title="T")
    report.write_json(tmp_path / "01_x" / "manifest.json", {"date": "D", "cpu": "C", "dataset": "S"})
    (tmp_path / "models").mkdir()
    out = report.assemble_tables(tmp_path)
    text = out.read_text()
    assert "## 01_x" in text and "| accuracy (%) |" in text and "91.5" in text and "models" not in text
    assert pd.read_csv(tmp_path / "01_x" / "paper_vs_run.csv").shape == (2, 4)
    assert not list(tmp_path.rglob(".tmp-*"))


def test_manifest_records_machine_and_versions(tmp_path):
    report.manifest(tmp_path, {"epochs": 3}, dataset=tmp_path / "missing")
    m = json.loads((tmp_path / "manifest.json").read_text())
    assert m["parameters"] == {"epochs": 3} and "numpy" in m["versions"] and m["cpu"]
    assert m["dataset_fingerprint"].startswith("unavailable")
