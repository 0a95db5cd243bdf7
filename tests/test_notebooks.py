"""The example notebooks (jupytext percent files, one source) execute in a Jupyter kernel of this venv."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

jupytext = pytest.importorskip("jupytext")
nbclient = pytest.importorskip("nbclient")
kernelspec = pytest.importorskip("ipykernel.kernelspec")

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "examples" / "notebooks").glob("*.py"))
KERNEL = "mrpctl-test-venv"


@pytest.fixture(scope="module")
def kernel_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A kernelspec for this interpreter (sys.executable), so a fresh machine needs no registered kernel."""
    prefix = tmp_path_factory.mktemp("jupyter")
    kernelspec.install(prefix=str(prefix), kernel_name=KERNEL, display_name="mrpctl test venv")
    spec = prefix / "share" / "jupyter" / "kernels" / KERNEL / "kernel.json"
    assert sys.executable in spec.read_text(encoding="utf-8")
    return prefix / "share" / "jupyter"


def test_there_are_notebooks() -> None:
    assert {p.name for p in NOTEBOOKS} >= {
        "paper_tour.py",
        "design_small_satellite.py",
        "monte_carlo_rules.py",
        "flight_loop.py",
        "tracking_nadir.py",
        "wheels_cubesat.py",
    }


@pytest.mark.slow
@pytest.mark.parametrize("source", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_executes_and_shows_figures(
    source: Path, kernel_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("JUPYTER_PATH", str(kernel_dir))
    monkeypatch.delenv("MPLBACKEND", raising=False)
    notebook = jupytext.read(source)
    client = nbclient.NotebookClient(
        notebook, kernel_name=KERNEL, timeout=240, resources={"metadata": {"path": str(tmp_path)}}
    )
    client.execute()
    outputs = [out for cell in notebook.cells if cell.cell_type == "code" for out in cell.get("outputs", [])]
    assert not [out for out in outputs if out.output_type == "error"]
    plotting = [cell for cell in notebook.cells if cell.cell_type == "code" and "plots.plot_" in cell.source]
    for cell in plotting:  # every plotting cell shows its figure: the library forced no non-interactive backend
        shown = [
            out
            for out in cell.get("outputs", [])
            if out.output_type in {"display_data", "execute_result"} and "image/png" in out.data
        ]
        assert len(shown) == 1, cell.source
    assert plotting
    text = "".join(out.get("text", "") for out in outputs if out.output_type == "stream")
    if source.stem == "paper_tour":
        assert "exact delay margin 1.5555" in text and "DelayAware     2 switches" in text
    elif source.stem == "monte_carlo_rules":
        lines = {line.split()[0]: line for line in text.splitlines() if line.strip()}
        assert "still switching   0%" in lines["DelayAware"] and "still switching   0%" not in lines["OnDelayed"]
    elif source.stem == "tracking_nadir":
        steady = {line.split()[0]: float(line.split()[-2]) for line in text.splitlines() if "steady pointing" in line}
        n_tau = float(text.split("n tau = ")[1].split()[0])
        assert steady["measurement"] < 1e-6 and steady["current"] == pytest.approx(n_tau, rel=0.01)
        assert "exact delay margin 1.5555" in text
    elif source.stem == "wheels_cubesat":
        settled = {line.split(":")[0]: float(line.split("at ")[1].split()[0]) for line in text.splitlines()
                   if "settled at" in line}  # fmt: skip
        assert "): designed" in text and settled["steering law"] < settled["PD alone"]
    elif source.stem == "flight_loop":
        changes = int(text.split("no hysteresis:")[1].split()[0])
        assert changes > 10 and "alpha = 1.2:   1 set change" in text
    else:
        assert "delay margin" in text and "at tau = 0.2 s: certified" in text and "status       converged" in text
