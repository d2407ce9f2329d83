"""Every notebook runs top to bottom, and is committed without outputs.

The notebooks run in quick mode (ADMITTANCE_NOTEBOOK_QUICK=1: shorter runs, fewer runs),
headless (MPLBACKEND=Agg), on a "python3" kernel that is this interpreter, in a temporary
working folder (they write their files under results/ there).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOK_DIR = Path(__file__).resolve().parents[1] / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))
# Longest a single cell may run, s (the slowest takes a few seconds in quick mode).
CELL_TIMEOUT = 300


def test_the_seven_notebooks_are_there_and_no_other():
    """The notebooks README.md lists, each run below (a new one must be listed here)."""
    assert [path.name for path in NOTEBOOKS] == [
        "build_your_own_loop.ipynb",
        "compare_controllers.ipynb",
        "flexiforce_sensor.ipynb",
        "grasp.ipynb",
        "reproduce_paper.ipynb",
        "spatial_arm.ipynb",
        "stability_analysis.ipynb",
    ]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda path: path.stem)
def test_notebook_is_committed_without_outputs(path):
    notebook = nbformat.read(path, as_version=4)
    nbformat.validate(notebook)
    assert notebook.metadata.kernelspec.name == "python3"
    for index, cell in enumerate(notebook.cells):
        if cell.cell_type == "code":
            assert cell.outputs == [], f"cell {index} has outputs"
            assert cell.execution_count is None, f"cell {index} has an execution count"


@pytest.fixture(scope="session")
def this_python_kernel(tmp_path_factory) -> Path:
    """A Jupyter data folder whose "python3" kernel runs this interpreter (the venv's)."""
    data = tmp_path_factory.mktemp("jupyter")
    kernel = data / "kernels" / "python3"
    kernel.mkdir(parents=True)
    spec = {
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": "Python 3 (tests)",
        "language": "python",
    }
    (kernel / "kernel.json").write_text(json.dumps(spec))
    return data


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda path: path.stem)
def test_notebook_runs_top_to_bottom(path, tmp_path, monkeypatch, this_python_kernel):
    monkeypatch.setenv("ADMITTANCE_NOTEBOOK_QUICK", "1")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    # JUPYTER_PATH comes first when Jupyter looks a kernel up.
    monkeypatch.setenv("JUPYTER_PATH", str(this_python_kernel))
    notebook = nbformat.read(path, as_version=4)
    client = NotebookClient(
        notebook,
        kernel_name="python3",
        timeout=CELL_TIMEOUT,
        resources={"metadata": {"path": str(tmp_path)}},
    )
    client.execute()  # raises CellExecutionError, naming the cell, on any error
    errors = [
        output
        for cell in notebook.cells
        for output in cell.get("outputs", [])
        if output.output_type == "error"
    ]
    assert errors == []
    # Every code cell ran, and the figures were drawn.
    code_cells = [cell for cell in notebook.cells if cell.cell_type == "code"]
    assert all(cell.execution_count for cell in code_cells)
    images = [
        output
        for cell in code_cells
        for output in cell.outputs
        if "image/png" in output.get("data", {})
    ]
    assert images, "no figure drawn"
