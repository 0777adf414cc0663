"""Plot a training run's progress.csv (written by baselines/ppo/ppo.py) as a PNG: success and return vs env steps.

    python scripts/plot_training.py --csv runs/<run>/progress.csv --out docs/images/training.png
    python scripts/plot_training.py --csv runs/<a>/progress.csv runs/<b>/progress.csv --title "ICM vs none" --window 20

Top panel: place and pick success of the training episodes (thick and thin lines) and the evaluation place
success (markers, where an evaluation ran); bottom panel: extrinsic return. One colour per curriculum stage,
raw values faint, a trailing moving average of --window rows on top (over the whole run, ignoring empty cells),
dashed vertical lines where the stage changes. Several --csv files overlay, one line style per run.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import tyro  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

REQUIRED = ("global_step", "stage", "pick_success", "place_success", "extrinsic_return", "eval_place_success")
NUMERIC = [c for c in REQUIRED if c != "stage"]
STAGE_COLORS = {"cp1": "tab:blue", "cp2": "tab:orange", "cp3": "tab:green", "cp4": "tab:red"}
EXTRA_COLORS = ["tab:purple", "tab:brown", "tab:pink", "tab:olive", "tab:cyan"]
RUN_STYLES = [("-", "o"), ("--", "s"), (":", "^"), ("-.", "D")]


@dataclass
class Args:
    csv: list[Path]
    """progress.csv of one or more runs (several overlay, one line style each)."""
    out: Path = Path("docs/images/training.png")
    """the PNG to write (its folder is created)."""
    title: Optional[str] = None
    """figure title (default: the run folder name(s))."""
    window: int = 10
    """rows in the trailing moving average."""


def load(path: Path) -> dict:
    """The needed columns as arrays (float, NaN for empty cells; stage as strings), or SystemExit."""
    if not path.is_file():
        raise SystemExit(f"{path}: no such file")
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        missing = [c for c in REQUIRED if c not in (reader.fieldnames or [])]
        if missing:
            raise SystemExit(f"{path}: missing columns: {', '.join(missing)}")
        rows = list(reader)
    if not rows:
        raise SystemExit(f"{path}: no rows")
    data = {c: np.array([float(r[c]) if r[c] not in ("", None) else np.nan for r in rows]) for c in NUMERIC}
    data["stage"] = [r["stage"] for r in rows]
    return data


def moving_average(x: np.ndarray, window: int) -> np.ndarray:
    """Trailing mean over the last `window` values, ignoring NaN; NaN where the window holds none."""
    valid = ~np.isnan(x)
    sums = np.cumsum(np.where(valid, x, 0.0))
    counts = np.cumsum(valid)
    sums[window:] = sums[window:] - sums[:-window]
    counts[window:] = counts[window:] - counts[:-window]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)


def stage_segments(stages: list[str]) -> list[tuple[str, int, int]]:
    """(stage, first row, row after the last) of each run of equal stages."""
    starts = [0] + [i for i in range(1, len(stages)) if stages[i] != stages[i - 1]]
    return [(stages[s], s, e) for s, e in zip(starts, starts[1:] + [len(stages)])]


def stage_color(stage: str, colors: dict) -> str:
    if stage not in colors:
        colors[stage] = EXTRA_COLORS[(len(colors) - len(STAGE_COLORS)) % len(EXTRA_COLORS)]
    return colors[stage]


def main(args: Args) -> None:
    if args.window < 1:
        raise SystemExit(f"--window must be at least 1, got {args.window}")
    if not args.csv:
        raise SystemExit("--csv: give at least one progress.csv")
    runs = [(p.parent.name or str(p), load(p)) for p in args.csv]
    colors = dict(STAGE_COLORS)
    fig, (ax_s, ax_r) = plt.subplots(2, 1, figsize=(10, 7), sharex=True, constrained_layout=True)
    for k, (name, d) in enumerate(runs):
        ls, marker = RUN_STYLES[k % len(RUN_STYLES)]
        x = d["global_step"]
        curves = [(ax_s, "place_success", 2.0), (ax_s, "pick_success", 1.0), (ax_r, "extrinsic_return", 2.0)]
        smooth = {col: moving_average(d[col], args.window) for _, col, _ in curves}
        for stage, s, e in stage_segments(d["stage"]):
            c = stage_color(stage, colors)
            seg = slice(s, min(e + 1, len(x)))  # reach the next stage's first point: no gap between colours
            for ax, col, lw in curves:
                ok = ~np.isnan(d[col][seg])  # join the raw line across empty cells
                ax.plot(x[seg][ok], d[col][seg][ok], color=c, ls=ls, lw=lw * 0.6, alpha=0.25)
                ax.plot(x[seg], smooth[col][seg], color=c, ls=ls, lw=lw)
            ev = d["eval_place_success"][s:e]
            ax_s.plot(x[s:e], ev, ls="none", marker=marker, ms=5, color=c, mec="black", mew=0.6)
            if s > 0:
                for ax in (ax_s, ax_r):
                    ax.axvline(x[s - 1], color="grey", ls="--", lw=1)
                label = stage if len(runs) == 1 else f"{name}: {stage}"
                ax_s.annotate(label, (x[s - 1], 1.0), xycoords=("data", "axes fraction"), xytext=(3, -3),
                              textcoords="offset points", va="top", fontsize=8, color="dimgrey")
    ax_s.set(ylabel="success rate", title="success", ylim=(-0.03, 1.05))
    ax_r.set(ylabel="extrinsic return", xlabel="env steps", title="extrinsic return")
    for ax in (ax_s, ax_r):
        ax.grid(alpha=0.3)
    used = list(dict.fromkeys(s for _, d in runs for s in d["stage"]))
    handles = [Patch(color=stage_color(s, colors), label=s) for s in used]
    handles += [Line2D([], [], color="black", lw=2, label="place success (train)"),
                Line2D([], [], color="black", lw=1, label="pick success (train)"),
                Line2D([], [], color="grey", ls="none", marker="o", mec="black", label="place success (eval)"),
                Line2D([], [], color="black", alpha=0.25, label=f"raw; solid = {args.window}-row average")]
    if len(runs) > 1:
        handles += [Line2D([], [], color="black", ls=RUN_STYLES[k % len(RUN_STYLES)][0],
                           marker=RUN_STYLES[k % len(RUN_STYLES)][1], label=name) for k, (name, _) in enumerate(runs)]
    ax_s.legend(handles=handles, loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=8, frameon=False)
    fig.suptitle(args.title or " vs ".join(name for name, _ in runs))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=120)
    plt.close(fig)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main(tyro.cli(Args))
