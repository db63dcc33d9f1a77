"""The code passes the linter and the formatter configured in pyproject.toml
(ruff: pyflakes, pycodestyle, import order, pyupgrade)."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CODE = ["jaxrock", "tests", "benchmarks"]


def _ruff(*args):
    return subprocess.run(
        [sys.executable, "-m", "ruff", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )


def test_ruff_check_passes():
    result = _ruff("check", *CODE)
    assert result.returncode == 0, result.stdout + result.stderr


def test_the_code_is_formatted():
    result = _ruff("format", "--check", *CODE)
    assert result.returncode == 0, result.stdout + result.stderr
