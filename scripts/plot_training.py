"""Plot training runs' progress.csv (written by baselines/ppo/ppo.py) as PNGs.

    python scripts/plot_training.py --csv runs/<run>/progress.csv --out docs/images/training.png
    python scripts/plot_training.py --csv runs/<a>/progress.csv runs/<b>/progress.csv --title "ICM vs none" --window 20
    python scripts/plot_training.py --csv campaign/paper_general_agent/progress.csv \
        campaign/paper_cp1_no_curiosity/progress.csv --max-steps 2000000   # cp1 with and without curiosity
    python scripts/plot_training.py --figure fig3 --csv campaign/paper_general_agent/progress.csv --out docs/images/paper_fig3.png
    python scripts/plot_training.py --figure fig4 --csv campaign/paper_general_agent/progress.csv \
        campaign/control_ceiling/progress.csv campaign/control_window/progress.csv campaign/control_flooring/progress.csv \
        --out docs/images/paper_fig4.png

`--figure progress` (the default):
Top panel: place and pick success of the training episodes (thick and thin lines) and the evaluation place
success (markers, where an evaluation ran); bottom panel: extrinsic return. One colour per curriculum stage,
raw values faint, a trailing moving average of --window rows on top (over the whole run, ignoring empty cells),
dashed vertical lines where the stage changes. Several --csv files overlay, one line style per run.

`--figure fig3` (the paper's Fig. 3): one run's extrinsic return per training episode against env steps,
one colour per curriculum stage, raw faint, moving average on top; beside it the intrinsic
(curiosity) return where the run has one. `--figure fig4` (the paper's Fig. 4): the first run's
last stage (the general agent's cp4) against the other runs (the control groups), each against env
steps since the start of that stage or run.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, Optional

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import tyro  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

REQUIRED = ("global_step", "stage", "pick_success", "place_success", "extrinsic_return", "eval_place_success")
FIGURE_REQUIRED = ("global_step", "stage", "extrinsic_return")
OPTIONAL = ("intrinsic_return",)
STAGE_COLORS = {"cp1": "tab:blue", "cp2": "tab:orange", "cp3": "tab:green", "cp4": "tab:red"}
EXTRA_COLORS = ["tab:purple", "tab:brown", "tab:pink", "tab:olive", "tab:cyan"]
RUN_STYLES = [("-", "o"), ("--", "s"), (":", "^"), ("-.", "D")]


@dataclass
class Args:
    csv: list[Path]
    """progress.csv of one or more runs (several overlay, one line style each; fig4: the general agent first)."""
    figure: Literal["progress", "fig3", "fig4"] = "progress"
    """what to draw (see the module docstring)."""
    out: Path = Path("docs/images/training.png")
    """the PNG to write (its folder is created)."""
    title: Optional[str] = None
    """figure title (default: the run folder name(s))."""
    window: int = 10
    """rows in the trailing moving average."""
    max_steps: Optional[int] = None
    """draw only the rows up to this env step (e.g. the paper setting's cp1 stage beside a run of that stage alone)."""


def load(path: Path, required: tuple[str, ...] = REQUIRED, max_steps: Optional[int] = None) -> dict:
    """The `required` columns (and the optional ones it has) as arrays (float, NaN for empty cells;
    stage as strings) of the rows up to `max_steps` env steps (all: None), or SystemExit."""
    if not path.is_file():
        raise SystemExit(f"{path}: no such file")
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        fields = reader.fieldnames or []
        missing = [c for c in required if c not in fields]
        if missing:
            raise SystemExit(f"{path}: missing columns: {', '.join(missing)}")
        rows = [r for r in reader if max_steps is None or float(r["global_step"]) <= max_steps]
    if not rows:
        raise SystemExit(f"{path}: no rows" + (f" up to env step {max_steps:,}" if max_steps is not None else ""))
    numeric = [c for c in required if c != "stage"] + [c for c in OPTIONAL if c in fields]
    data = {c: np.array([float(r[c]) if r[c] not in ("", None) else np.nan for r in rows]) for c in numeric}
    data["stage"] = [r["stage"] for r in rows]
    return data


def run_label(path: Path, paths: list[Path]) -> str:
    """A run's name: its folder (runs/<run>/progress.csv), or the file's own name where several share a folder."""
    shared = sum(p.parent == path.parent for p in paths) > 1
    return path.stem if shared or not path.parent.name else path.parent.name


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
    if args.figure == "fig3":
        fig = figure3(args)
    elif args.figure == "fig4":
        fig = figure4(args)
    else:
        fig = progress_figure(args)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=120)
    plt.close(fig)
    print(f"wrote {args.out}")


def raw_and_average(ax, x: np.ndarray, y: np.ndarray, window: int, color: str, label: Optional[str] = None) -> None:
    """`y` against `x`, raw faint (joined across empty cells) and its trailing moving average on top."""
    ok = ~np.isnan(y)
    ax.plot(x[ok], y[ok], color=color, lw=0.8, alpha=0.25)
    ax.plot(x, moving_average(y, window), color=color, lw=2, label=label)


def figure3(args: Args):
    """The paper's Fig. 3 for one run: returns against env steps, a colour per stage."""
    if len(args.csv) != 1:
        raise SystemExit("--figure fig3: give one progress.csv (the general agent's)")
    d = load(args.csv[0], FIGURE_REQUIRED, args.max_steps)
    intrinsic = "intrinsic_return" in d and not np.isnan(d["intrinsic_return"]).all()
    fig, axes = plt.subplots(1, 2 if intrinsic else 1, figsize=(13 if intrinsic else 8, 4.5), constrained_layout=True,
                             squeeze=False)
    colors, x = dict(STAGE_COLORS), d["global_step"]
    panels = [("extrinsic_return", "extrinsic return (Algorithm 1)")] + ([("intrinsic_return", "intrinsic (curiosity) return")]
                                                                          if intrinsic else [])
    for ax, (col, title) in zip(axes[0], panels):
        smooth = moving_average(d[col], args.window)
        for stage, s, e in stage_segments(d["stage"]):
            c = stage_color(stage, colors)
            seg = slice(s, min(e + 1, len(x)))
            ok = ~np.isnan(d[col][seg])
            ax.plot(x[seg][ok], d[col][seg][ok], color=c, lw=0.8, alpha=0.25)
            ax.plot(x[seg], smooth[seg], color=c, lw=2, label=stage if col == "extrinsic_return" else None)
        ax.set(xlabel="env steps", ylabel="return per episode", title=title)
        ax.grid(alpha=0.3)
    axes[0][0].axhline(3.0, color="grey", ls=":", lw=1)
    axes[0][0].legend(title=f"stage (solid: {args.window}-row average)", fontsize=8)
    fig.suptitle(args.title or f"{args.csv[0].parent.name}: training episodes' return")
    return fig


def figure4(args: Args):
    """The paper's Fig. 4: the first run's last stage against the other runs, from each one's start."""
    if len(args.csv) < 2:
        raise SystemExit("--figure fig4: give the general agent's progress.csv first, then the control groups'")
    general = load(args.csv[0], FIGURE_REQUIRED, args.max_steps)
    last = stage_segments(general["stage"])[-1]
    fig, ax = plt.subplots(figsize=(9, 4.5), constrained_layout=True)
    s = last[1]
    start = general["global_step"][s - 1] if s > 0 else 0
    raw_and_average(ax, general["global_step"][s:] - start, general["extrinsic_return"][s:], args.window, "tab:red",
                    f"{args.csv[0].parent.name} ({last[0]} stage)")
    for k, path in enumerate(args.csv[1:]):
        d = load(path, FIGURE_REQUIRED, args.max_steps)
        raw_and_average(ax, d["global_step"], d["extrinsic_return"], args.window, EXTRA_COLORS[k % len(EXTRA_COLORS)],
                        path.parent.name)
    ax.axhline(3.0, color="grey", ls=":", lw=1)
    ax.set(xlabel="env steps (from the start of the stage or run)", ylabel="extrinsic return per episode",
           title=args.title or "cp4 of the general agent and the control groups")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, title=f"solid: {args.window}-row average")
    return fig


def progress_figure(args: Args):
    runs = [(run_label(p, args.csv), load(p, max_steps=args.max_steps)) for p in args.csv]
    colors = dict(STAGE_COLORS)
    used = list(dict.fromkeys(s for _, d in runs for s in d["stage"]))
    # runs that all train in one stage (the refinements at cp4) are told apart by colour, not by line style alone
    by_run = len(used) == 1 and len(runs) > 1
    fig, (ax_s, ax_r) = plt.subplots(2, 1, figsize=(10, 7), sharex=True, constrained_layout=True)
    for k, (name, d) in enumerate(runs):
        ls, marker = RUN_STYLES[k % len(RUN_STYLES)]
        x = d["global_step"]
        curves = [(ax_s, "place_success", 2.0), (ax_s, "pick_success", 1.0), (ax_r, "extrinsic_return", 2.0)]
        smooth = {col: moving_average(d[col], args.window) for _, col, _ in curves}
        for stage, s, e in stage_segments(d["stage"]):
            c = f"C{k}" if by_run else stage_color(stage, colors)
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
    handles = [] if by_run else [Patch(color=stage_color(s, colors), label=s) for s in used]
    handles += [Line2D([], [], color="black", lw=2, label="place success (train)"),
                Line2D([], [], color="black", lw=1, label="pick success (train)"),
                Line2D([], [], color="grey", ls="none", marker="o", mec="black", label="place success (eval)"),
                Line2D([], [], color="black", alpha=0.25, label=f"raw; solid = {args.window}-row average")]
    if len(runs) > 1:
        handles += [Line2D([], [], color=f"C{k}" if by_run else "black", ls=RUN_STYLES[k % len(RUN_STYLES)][0],
                           marker=RUN_STYLES[k % len(RUN_STYLES)][1], label=name) for k, (name, _) in enumerate(runs)]
    ax_s.legend(handles=handles, loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=8, frameon=False)
    fig.suptitle(args.title or " vs ".join(name for name, _ in runs))
    return fig


if __name__ == "__main__":
    main(tyro.cli(Args))
