"""Command lines written down from configured Args: a run or evaluation set up in code (experiments/) records the
command a reader can type to repeat it, not its caller's argv."""

from __future__ import annotations

from typing import Any, Iterable, Mapping


def flags(values: Mapping[str, Any], defaults: Mapping[str, Any], always: Iterable[str] = ()) -> list[str]:
    """tyro flags that set `values`: those that differ from `defaults`, and those named in `always` (so that a later
    change of a default does not change what a recorded command runs). Booleans become --x / --no-x; a tuple's
    values all follow its one flag, as tyro reads them."""
    always, out = set(always), []
    for name, value in values.items():
        if name not in always and value == defaults[name]:
            continue
        flag = "--" + name.replace("_", "-")
        if isinstance(value, bool):
            out.append(flag if value else "--no-" + name.replace("_", "-"))
        elif isinstance(value, (tuple, list)):
            out += [flag, *map(str, value)]
        else:
            out += [flag, str(value)]
    return out
