"""The notebooks run as written (their small configuration, in this process:
their compiles are shared with the other tests, which a kernel of their own
would redo). The notebooks assert what they show."""

import json
from pathlib import Path

import matplotlib.pyplot as plt
import pytest

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"


@pytest.mark.parametrize(
    "name", ["behavior_maps", "isolator_tuning", "records", "museum_study"]
)
def test_notebook_runs(name, tmp_path, monkeypatch):
    cells = json.loads((NOTEBOOKS / f"{name}.ipynb").read_text())["cells"]
    code = ["".join(c["source"]) for c in cells if c["cell_type"] == "code"]
    assert code, f"{name}.ipynb has no code"
    monkeypatch.setenv("JAXROCK_SMALL", "1")
    monkeypatch.chdir(tmp_path)
    namespace = {}
    for i, source in enumerate(code):
        exec(compile(source, f"{name}.ipynb, cell {i}", "exec"), namespace)
    plt.close("all")
