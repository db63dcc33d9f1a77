"""What every benchmark script does with its results: print the Markdown
table, and write it and the rows to `benchmarks/results/NAME.{md,json}`."""

import json
from pathlib import Path

FOLDER = Path(__file__).resolve().parent / "results"


def markdown_table(rows, columns: list[tuple[str, str]]) -> list[str]:
    """The lines of a Markdown table of `rows` (dicts): a column a pair of
    `columns`, its header and its cells' template, which `str.format` fills
    with the row's fields (e.g. "{run_s:.2f}")."""
    lines = ["| " + " | ".join(h for h, _ in columns) + " |"]
    lines += ["|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(t.format(**r) for _, t in columns) + " |" for r in rows]
    return lines


def write_results(name: str, rows, md: str | list[str], folder=None) -> None:
    """Print `md` (a table, or its lines) and write `NAME.md` and `NAME.json`
    (`rows`, any JSON-serializable value) to `folder` (default: the results
    folder)."""
    text = md if isinstance(md, str) else "\n".join(md)
    print(text)
    folder = FOLDER if folder is None else Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{name}.json").write_text(json.dumps(rows, indent=2))
    (folder / f"{name}.md").write_text(text + "\n")
