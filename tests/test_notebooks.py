"""Every example notebook runs top to bottom in a fresh kernel, without error, and draws a figure.

The notebooks are executed with nbclient in a kernel started from this interpreter (a kernelspec
written to a temporary folder that comes first on `JUPYTER_PATH`, so a `python3` kernelspec the
user installed elsewhere cannot substitute another Python), with the inline matplotlib backend
and `examples/notebooks` as the working directory. The tests skip when nbclient, nbformat or
ipykernel is missing; the `test` extra installs them.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

NOTEBOOKS = Path(__file__).parents[1] / "examples" / "notebooks"
NAMES = (
    "01_sig_kernel.ipynb",
    "02_line_fitting.ipynb",
    "03_convexity_region.ipynb",
    "04_false_loops.ipynb",
    "05_your_data.ipynb",
    "06_online.ipynb",
)
TIMEOUT_S = 120
"""Budget of one notebook, start to end (each is meant to take well under a minute)."""

KERNEL_NAME = "egnc-tests-python"


def test_every_notebook_is_listed():
    assert sorted(path.name for path in NOTEBOOKS.glob("*.ipynb")) == sorted(NAMES)


@pytest.mark.parametrize("name", NAMES)
def test_notebook_is_committed_without_outputs(name):
    # Outputs are produced by running the notebook (here and in Jupyter), not stored: the files
    # stay small and their diffs readable.
    notebook = json.loads((NOTEBOOKS / name).read_text(encoding="utf-8"))
    code_cells = [cell for cell in notebook["cells"] if cell["cell_type"] == "code"]
    assert code_cells
    assert all(cell["outputs"] == [] and cell["execution_count"] is None for cell in code_cells)


@pytest.fixture(scope="module")
def kernel_name(tmp_path_factory):
    """A kernelspec that runs ipykernel in this interpreter, first on `JUPYTER_PATH` for the module."""
    pytest.importorskip("nbclient")
    pytest.importorskip("nbformat")
    pytest.importorskip("ipykernel")
    pytest.importorskip("matplotlib")
    data_dir = tmp_path_factory.mktemp("jupyter")
    spec_dir = data_dir / "kernels" / KERNEL_NAME
    spec_dir.mkdir(parents=True)
    spec = {
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": "egnc tests",
        "language": "python",
        # Figures must come back as PNG outputs even when MPLBACKEND is set to a file backend.
        "env": {"MPLBACKEND": "module://matplotlib_inline.backend_inline"},
    }
    (spec_dir / "kernel.json").write_text(json.dumps(spec), encoding="utf-8")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("JUPYTER_PATH", os.pathsep.join(filter(None, [str(data_dir), os.environ.get("JUPYTER_PATH")])))
        yield KERNEL_NAME


@pytest.fixture(scope="module")
def run_notebook(kernel_name):
    """`name -> (executed notebook, seconds)`, each notebook executed once per module."""
    import nbformat
    from nbclient import NotebookClient

    runs = {}

    def run(name: str):
        if name not in runs:
            notebook = nbformat.read(NOTEBOOKS / name, as_version=4)
            client = NotebookClient(
                notebook,
                timeout=TIMEOUT_S,
                kernel_name=kernel_name,
                resources={"metadata": {"path": str(NOTEBOOKS)}},  # the kernel's working directory
            )
            started = time.perf_counter()
            client.execute()  # raises CellExecutionError, naming the cell, on the first error
            runs[name] = notebook, time.perf_counter() - started
        return runs[name]

    return run


def code_outputs(notebook) -> list:
    """Every output of every code cell, in order."""
    return [output for cell in notebook.cells if cell.cell_type == "code" for output in cell.outputs]


@pytest.mark.parametrize("name", NAMES)
def test_notebook_runs_and_draws(name, run_notebook):
    notebook, elapsed = run_notebook(name)
    outputs = code_outputs(notebook)
    assert not [output for output in outputs if output.output_type == "error"]
    assert any("image/png" in output.get("data", {}) for output in outputs), f"{name} drew no figure"
    assert elapsed < TIMEOUT_S, f"{name} took {elapsed:.0f} s"


def test_line_fitting_prints_its_answer(run_notebook):
    """The Fig. 2 notebook ends with an explicit answer line; EGNC reaches a = 1 in fewer stages."""
    notebook, _ = run_notebook("02_line_fitting.ipynb")
    text = "".join(output.get("text", "") for output in code_outputs(notebook))
    answer = re.search(
        r"^EGNC: a = ([\d.]+) after (\d+) stages; riSAM: a = ([\d.]+) after (\d+) stages$", text, re.MULTILINE
    )
    assert answer, text
    egnc_a, egnc_stages, risam_a, risam_stages = float(answer[1]), int(answer[2]), float(answer[3]), int(answer[4])
    assert abs(egnc_a - 1.0) < 0.1 and abs(risam_a - 1.0) < 0.1
    assert egnc_stages < risam_stages == 5


def test_online_notebook_prints_its_answer(run_notebook):
    """The online notebook ends with its iteration totals; EGNC's schedule spends fewer than riSAM's."""
    notebook, _ = run_notebook("06_online.ipynb")
    text = "".join(output.get("text", "") for output in code_outputs(notebook))
    answer = re.search(r"^EGNC: (\d+) iterations; riSAM: (\d+) iterations; ratio [\d.]+$", text, re.MULTILINE)
    assert answer, text
    assert 0 < int(answer[1]) < int(answer[2])
    assert "egnc.online.replay makes the same updates and the same final decisions as the loop above" in text


def test_readme_snippet_prints_the_line_it_shows():
    """examples/notebooks/README.md's Fig. 2 snippet runs at a plain prompt and prints what the README says."""
    readme = (NOTEBOOKS / "README.md").read_text(encoding="utf-8")
    snippet = re.search(r"```python\n(.*?)```", readme, re.DOTALL)
    assert snippet, "README.md has no python snippet"
    process = subprocess.run(
        [sys.executable, "-c", snippet[1]],
        check=False,
        capture_output=True,
        text=True,
        timeout=TIMEOUT_S,
        cwd=NOTEBOOKS,
    )
    assert process.returncode == 0, process.stderr
    line = process.stdout.strip()
    assert line.startswith("EGNC: a = ") and f"```\n{line}\n```" in readme, process.stdout
