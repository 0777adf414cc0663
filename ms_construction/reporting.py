"""Writes script-produced sections into the docs, each between its own markers, so several scripts
can share one page (docs/BENCHMARKS.md, docs/RESULTS.md) without overwriting each other."""

from __future__ import annotations

import json
import time
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


class WallTimes:
    """Wall time per step of a multi-step command (demonstrations, PPO, validation, ...), kept in a JSON
    file of its run folder (`{"wall_s": {step: seconds}}`) so that a resumed command adds to it."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self.record = json.loads(self.path.read_text()) if self.path.exists() else {"wall_s": {}}

    def timed(self, step: str, fn):
        """`fn()`, its wall time added to `step` (and written) whether it returns or raises."""
        t = time.time()
        try:
            return fn()
        finally:
            self.record["wall_s"][step] = self.record["wall_s"].get(step, 0.0) + time.time() - t
            self.path.write_text(json.dumps(self.record, indent=1) + "\n")
