"""Writes script-produced sections into the docs, each between its own markers, so several scripts
can share one page (docs/BENCHMARKS.md, docs/RESULTS.md) without overwriting each other."""

from __future__ import annotations

from pathlib import Path


def update_section(path: Path, name: str, body: str, title: str) -> None:
    """Replace (or append) the section `name` of the markdown file `path`."""
    path = Path(path)
    begin, end = f"<!-- begin {name} (generated) -->", f"<!-- end {name} -->"
    block = f"{begin}\n{body.rstrip()}\n{end}"
    text = path.read_text() if path.exists() else f"# {title}\n"
    if begin in text and end in text:
        head, rest = text.split(begin, 1)
        text = head + block + rest.split(end, 1)[1]
    else:
        text = text.rstrip() + "\n\n" + block + "\n"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
