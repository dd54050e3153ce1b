"""Every example notebook runs top to bottom in a fresh kernel, without error, and draws a figure.

The notebooks are executed with nbclient in a kernel started from this interpreter (a kernelspec
written to a temporary folder that comes first on `JUPYTER_PATH`, so a `python3` kernelspec the
user installed elsewhere cannot substitute another Python), with the inline matplotlib backend
and `examples/notebooks` as the working directory. The tests skip when nbclient, nbformat or
ipykernel is missing; the `test` extra installs them.

The Rerun cells of `04` and `06` record into an `.rrd` file, which is read back here, and show it
in the notebook's viewer widget when the `rerun` extra is installed; a second kernelspec hides the
Rerun SDK (a `rerun` package that fails to import comes first on its `PYTHONPATH`) to check that
`04` then says what to install and runs on.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import shutil
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
    "07_gnss_priors.ipynb",
)
TIMEOUT_S = 120
"""Budget of one notebook, start to end (each is meant to take well under a minute)."""

KERNEL_NAME = "egnc-tests-python"
HIDDEN_RERUN_KERNEL_NAME = "egnc-tests-python-without-rerun"
WIDGET = "application/vnd.jupyter.widget-view+json"
"""The output type of a Jupyter widget, here the Rerun viewer."""


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
    """Kernelspecs that run ipykernel in this interpreter, first on `JUPYTER_PATH` for the module:
    `KERNEL_NAME`, and `HIDDEN_RERUN_KERNEL_NAME`, in which `import rerun` fails."""
    pytest.importorskip("nbclient")
    pytest.importorskip("nbformat")
    pytest.importorskip("ipykernel")
    pytest.importorskip("matplotlib")
    data_dir = tmp_path_factory.mktemp("jupyter")
    hidden = tmp_path_factory.mktemp("hidden") / "rerun"
    hidden.mkdir()
    (hidden / "__init__.py").write_text('raise ImportError("the Rerun SDK is hidden from this kernel")\n')
    python_path = os.pathsep.join(filter(None, [str(hidden.parent), os.environ.get("PYTHONPATH")]))
    for name, env in ((KERNEL_NAME, {}), (HIDDEN_RERUN_KERNEL_NAME, {"PYTHONPATH": python_path})):
        spec_dir = data_dir / "kernels" / name
        spec_dir.mkdir(parents=True)
        spec = {
            "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
            "display_name": "egnc tests",
            "language": "python",
            # Figures must come back as PNG outputs even when MPLBACKEND is set to a file backend.
            "env": {"MPLBACKEND": "module://matplotlib_inline.backend_inline", **env},
        }
        (spec_dir / "kernel.json").write_text(json.dumps(spec), encoding="utf-8")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("JUPYTER_PATH", os.pathsep.join(filter(None, [str(data_dir), os.environ.get("JUPYTER_PATH")])))
        yield KERNEL_NAME


@pytest.fixture(scope="module")
def run_notebook(kernel_name):
    """`(name, kernel) -> (executed notebook, seconds)`, each executed once per module."""
    import nbformat
    from nbclient import NotebookClient

    runs = {}

    def run(name: str, kernel: str = kernel_name):
        if (name, kernel) not in runs:
            notebook = nbformat.read(NOTEBOOKS / name, as_version=4)
            client = NotebookClient(
                notebook,
                timeout=TIMEOUT_S,
                kernel_name=kernel,
                resources={"metadata": {"path": str(NOTEBOOKS)}},  # the kernel's working directory
            )
            started = time.perf_counter()
            client.execute()  # raises CellExecutionError, naming the cell, on the first error
            runs[name, kernel] = notebook, time.perf_counter() - started
        return runs[name, kernel]

    return run


def code_outputs(notebook) -> list:
    """Every output of every code cell, in order."""
    return [output for cell in notebook.cells if cell.cell_type == "code" for output in cell.outputs]


def code_text(notebook) -> str:
    """The text every code cell printed, in order."""
    return "".join(output.get("text", "") for output in code_outputs(notebook))


def recorded_file(notebook) -> Path | None:
    """The `.rrd` file the notebook's Rerun cell reports, or None when the Rerun SDK is not installed
    (the cell then says what to install); asserts that the viewer widget was shown when it can be."""
    text = code_text(notebook)
    if importlib.util.find_spec("rerun") is None:
        assert "no recording: recording for the Rerun viewer needs the Rerun SDK: pip install 'egnc[rerun]'" in text
        return None
    found = re.search(r"^recording: (\S+\.rrd) \(", text, re.MULTILINE)
    assert found, text
    widgets = [output for output in code_outputs(notebook) if WIDGET in output.get("data", {})]
    if importlib.util.find_spec("rerun_notebook") is None:
        assert "a viewer inside a notebook needs the rerun-notebook package" in text
    else:
        assert widgets, "the Rerun viewer was not shown"
    return Path(found[1])


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
    text = code_text(notebook)
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
    text = code_text(notebook)
    answer = re.search(r"^EGNC: (\d+) iterations; riSAM: (\d+) iterations; ratio [\d.]+$", text, re.MULTILINE)
    assert answer, text
    assert 0 < int(answer[1]) < int(answer[2])
    assert "egnc.online.replay makes the same updates and the same final decisions as the loop above" in text


def test_gnss_notebook_rejects_the_multipath_burst_and_the_false_loops(run_notebook):
    """07: trusting the fixes bends the map; as candidates, every moved fix and false loop is rejected, nothing else."""
    notebook, _ = run_notebook("07_gnss_priors.ipynb")
    text = code_text(notebook)
    trusted = re.search(r"^fixes trusted +: ATE +([\d.]+) m; (\d+) loops and 0 fixes rejected", text, re.MULTILINE)
    default = re.search(
        r"^fixes as candidates \(default\): ATE +([\d.]+) m; (\d+) loops and (\d+) fixes rejected; "
        r"loops P = 1.000, R = 1.000, priors P = 1.000, R = 1.000;",
        text,
        re.MULTILINE,
    )
    assert trusted and default, text
    false_loops, moved = re.search(r"(\d+) of them false\), \d+ fixes of which (\d+) moved by multipath", text).groups()
    assert (default[2], default[3]) == (false_loops, moved) and int(moved) > 0
    assert float(default[1]) < 0.1 and float(trusted[1]) > 1.0  # ATE, metres
    written = Path(re.search(r"^egnc-corrupt .* -o (\S+\.g2o)$", text, re.MULTILINE)[1])
    assert written.is_file() and written.with_suffix(".labels.json").is_file()
    shutil.rmtree(written.parent)  # the notebook's temporary folder


def test_false_loops_notebook_table_says_what_its_text_says(run_notebook):
    """04: every graduated method rejects exactly the false loops; EGNC and riSAM take as many stages, GNC more."""
    notebook, _ = run_notebook("04_false_loops.ipynb")
    rows = re.findall(r"^([\w-]+) +[\d.]+ +(\d+) +\d+ +([\d.]+) +([\d.]+) ", code_text(notebook), re.MULTILINE)
    table = {method: (int(stages), float(p), float(r)) for method, stages, p, r in rows}
    assert set(table) == {"l2", "egnc", "risam", "gnc-tls", "gnc-gm"}
    assert all(table[method][1:] == (1.0, 1.0) for method in ("egnc", "risam", "gnc-tls", "gnc-gm"))
    assert table["egnc"][0] == table["risam"][0] < min(table["gnc-tls"][0], table["gnc-gm"][0])


def test_false_loops_notebook_records_its_solve_for_rerun(run_notebook):
    """04's recording holds every EGNC stage (as many as its table counts) and the false loops rejected."""
    notebook, _ = run_notebook("04_false_loops.ipynb")
    path = recorded_file(notebook)
    if path is None:
        return
    from test_rerun import column, read_back, timeline

    text = code_text(notebook)
    stages = int(re.search(r"^egnc\s+[\d.]+\s+(\d+)\s", text, re.MULTILINE)[1])  # the table's row
    false_loops = int(re.search(r"loop closures of which (\d+) are false", text)[1])
    batches = read_back(path)
    shutil.rmtree(path.parent)
    assert timeline(batches["/stages/trajectory"], "stage") == list(range(stages + 1))  # 0: the initial guess
    assert timeline(batches["/stages/cost"], "stage") == list(range(1, stages + 1))
    assert len(column(batches["/result/loops/rejected"], "Arrows2D:origins")[0]) == false_loops


def test_online_notebook_records_every_update_for_rerun(run_notebook):
    """06's recording holds every update of its replay and one line per update with a loop closure."""
    notebook, _ = run_notebook("06_online.ipynb")
    path = recorded_file(notebook)
    if path is None:
        return
    from test_rerun import column, read_back, timeline

    counts = re.search(r"^egnc : (\d+) updates, (\d+) with a loop closure", code_text(notebook), re.MULTILINE)
    updates, with_loops = int(counts[1]), int(counts[2])
    batches = read_back(path)
    shutil.rmtree(path.parent)
    assert timeline(batches["/online/latency_ms"], "update") == list(range(1, updates + 1))
    assert len(column(batches["/online/log"], "TextLog:text")) == with_loops > 0


def test_rerun_cells_say_what_to_install_without_rerun(run_notebook):
    """Without the Rerun SDK, 04 runs to its end and its Rerun cell names the extra instead."""
    notebook, _ = run_notebook("04_false_loops.ipynb", HIDDEN_RERUN_KERNEL_NAME)
    outputs = code_outputs(notebook)
    assert not [output for output in outputs if output.output_type == "error"]
    text = code_text(notebook)
    assert "no recording: recording for the Rerun viewer needs the Rerun SDK: pip install 'egnc[rerun]'" in text
    assert "recording: " not in text.replace("no recording: ", "")
    assert not [output for output in outputs if WIDGET in output.get("data", {})]


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
