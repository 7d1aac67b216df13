"""An evaluation's report: the table printed, the JSON written where asked, read back the same."""

from __future__ import annotations

import json

from training.reports import publish


def test_publish_prints_the_table_and_writes_the_report(tmp_path, capsys):
    report = {"half": "test", "rows": [{"style": "proud", "top1": 0.5}]}
    path = tmp_path / "runs" / "eval" / "report.json"  # its folders do not exist yet
    publish(report, "| style | top1 |", path)
    assert "| style | top1 |" in capsys.readouterr().out
    assert json.loads(path.read_text()) == report


def test_publish_without_a_path_writes_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    publish({"n": 1}, "table", None)
    assert capsys.readouterr().out.strip() == "table"
    assert list(tmp_path.iterdir()) == []
