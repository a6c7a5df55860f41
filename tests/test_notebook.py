"""examples/quickstart.ipynb: committed executed, without machine paths; runs top to bottom (slow, real data)."""
import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOK = ROOT / "examples" / "quickstart.ipynb"


def runner():
    spec = importlib.util.spec_from_file_location("run_notebook", ROOT / "examples" / "run_notebook.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_committed_notebook_is_executed_and_clean():
    nb = json.loads(NOTEBOOK.read_text())
    code = [c for c in nb["cells"] if c["cell_type"] == "code"]
    assert len(code) >= 10
    assert [c["execution_count"] for c in code] == list(range(1, len(code) + 1))  # top to bottom, once
    assert all(c["outputs"] for c in code)
    assert not [o for c in code for o in c["outputs"] if o["output_type"] == "error"]
    assert not [o for c in code for o in c["outputs"] if o.get("name") == "stderr"]
    assert all("execution" not in c["metadata"] for c in code)
    images = [o for c in code for o in c["outputs"] if "image/png" in o.get("data", {})]
    assert len(images) >= 4
    text = "".join("".join(c["source"]) for c in code)
    for step in ("load_frame", "report_table", "plot_track", "evaluate", "vs_ekf", "plot_paired", "export_mcap"):
        assert step in text, step


def test_committed_notebook_names_no_machine_path():
    assert runner().machine_paths(json.loads(NOTEBOOK.read_text())) == []


@pytest.mark.slow
def test_notebook_runs_top_to_bottom(bohai_dir, tmp_path, monkeypatch):
    pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    monkeypatch.setenv("REPLAY_SHARED", str(bohai_dir.parents[1]))
    nb = runner().execute(NOTEBOOK, tmp_path / "run.ipynb", timeout=900)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert not [o for c in code for o in c.outputs if o.output_type == "error"]
    paired = next(c for c in code if "pos_rmse_vs_ekf_ci95" in c.source and "board[" in c.source)
    table = paired.outputs[0]["data"]["text/plain"]
    assert "stckf" in table and "pf" in table
    mcap = next(c for c in code if "export_mcap" in c.source)
    assert "wrote quickstart.mcap:" in mcap.outputs[0]["text"]
