"""The refinement runs in docs/: what each run of `python -m experiments.refine` did on the validation
seeds, as a table and failures by kind in docs/experiments/general_agent.md and a curve as a PNG.

    python -m experiments.refine_report --runs runs/refine runs/refine2 --write-results

A run folder is summarized (the settings its PPO checkpoint saved; the clone's validation and each
snapshot's, with every failed episode) into docs/data/refine/<folder name>.json; a .json path is read as
such a summary, so the docs regenerate from docs/data alone once the runs are gone:

    python -m experiments.refine_report --runs docs/data/refine/refine.json docs/data/refine/refine2.json --write-results

Failure kinds at cp4: baselines/ppo/evaluation.py's `failures`.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import torch  # noqa: E402
import tyro  # noqa: E402

from baselines.ppo.evaluation import failures, kinds  # noqa: E402
from experiments.refine import beats, best_snapshot  # noqa: E402
from ms_construction.reporting import update_section  # noqa: E402
from baselines.ppo.checkpoints import load_checkpoint

SETTINGS = ("learning_rate", "gamma", "start_states_share", "residual_scale", "residual_l2_coef", "num_envs", "num_steps",
            "critic_warmup_iterations", "bootstrap_at_done", "target_kl", "reward_mode", "reward_scale",
            "task_weights", "obs_elapsed_time", "start_states_keep_clock", "residual_of")
CLONE_NAME = "general_agent_clone.pt"
TASKS = {"CeilingInstallation-v1": "ceiling", "WindowInstallation-v1": "window", "Flooring-v1": "flooring"}


@dataclass
class Args:
    runs: tuple[Path, ...]
    """refine.py run folders (summarized into --data-dir) or their summaries (.json), in the table's order."""
    data_dir: Path = Path("docs/data/refine")
    """where run folders' summaries go."""
    out: Path = Path("docs/images/refine_validation.png")
    """the curve: each run's validation place success per task against its PPO env steps."""
    write_results: bool = False
    """write the section `refinement` of docs/experiments/general_agent.md."""
    results: Path = Path("docs/experiments/general_agent.md")


def validation_summary(path: Path) -> dict:
    data = json.loads(path.read_text())
    return {env_id: dict(episodes=r["episodes"], place_success=r["place_success"], ci95=r["place_success_ci95"],
                         pick_success=r["pick_success"], failures=failures(r["episode_results"]))
            for env_id, r in data["tasks"].items()}


def summarize(run: Path) -> dict:
    """A refine.py run folder as one JSON-able record."""
    ckpt = load_checkpoint(run / "ppo" / "checkpoint.pt")
    saved = ckpt["args"]
    validations, clone = {}, None
    for path in sorted(run.glob("val*_*.json")):
        which = path.stem.split("_", 1)[1]
        if which == "clone":
            clone = validation_summary(path)
        elif which == "refined":  # a run before refine.py validated snapshots: its one validation, at its end
            validations[int(ckpt["progress"]["global_step"])] = validation_summary(path)
        elif re.fullmatch(r"\d+", which):
            validations[int(which)] = validation_summary(path)
    if clone is None:
        raise SystemExit(f"{run}: no validation of the clone (val<episodes>_clone.json); run refine.py there first")
    settings = {k: saved.get(k) for k in SETTINGS}
    if (run / "failure_states.pt").exists():
        settings["bank_offsets"] = list(torch.load(run / "failure_states.pt", map_location="cpu", weights_only=False)["offsets"])
    summary = dict(run=run.name, settings=settings, ppo_steps=int(ckpt["progress"]["global_step"]),
                   clone=clone, validations={str(k): v for k, v in sorted(validations.items())})
    # refine.py's confirmation: the best snapshot and the clone again, on fresh seeds (confirm<episodes>_<which>.json)
    confirmed = {path.stem.split("_", 1)[1]: validation_summary(path) for path in sorted(run.glob("confirm*_*.json"))}
    steps = [k for k in confirmed if k.isdigit()]
    if "clone" in confirmed and len(steps) == 1:
        summary["confirmation"] = dict(env_steps=int(steps[0]), clone=confirmed["clone"], snapshot=confirmed[steps[0]])
        # refine.py's last bar: the agent shipped at the time (confirm<episodes>_shipped_<its hash>.json)
        shipped = [k for k in confirmed if k.startswith("shipped_")]
        if shipped:
            summary["confirmation"]["shipped"] = confirmed[shipped[0]]
    return summary


def load(path: Path, data_dir: Path) -> dict:
    if path.suffix == ".json":
        return json.loads(path.read_text())
    if not (path / "ppo" / "checkpoint.pt").exists():
        raise SystemExit(f"{path}: neither a refine.py run folder (no ppo/checkpoint.pt) nor a summary (.json)")
    summary = summarize(path)
    data_dir.mkdir(parents=True, exist_ok=True)
    (data_dir / f"{path.name}.json").write_text(json.dumps(summary, indent=1) + "\n")
    return summary


def pct(v: float) -> str:
    return f"{100 * v:.1f}"


def report(runs: list[dict]) -> str:
    lines = ["| run | settings | env steps | " + " | ".join(f"{t} placed % [95% CI]" for t in TASKS.values()) + " |",
             "|---|---|---|" + "---|" * len(TASKS)]
    for r in runs:
        s = r["settings"]
        base = Path(s.get("residual_of") or CLONE_NAME).name  # a second round refines a refined agent, not the clone
        setting = ((f"on {base}, " if base != CLONE_NAME else "")
                   + (f"{s['reward_mode']} reward x {s['reward_scale']:g}, " if s.get("reward_mode", "sparse") != "sparse" else "")
                   + f"lr {s['learning_rate']:g}, gamma {s['gamma']}, bank share {s['start_states_share']}, "
                   f"scale {s['residual_scale']}, {s['num_envs']} envs x {s['num_steps']}"
                   + (f", L2 anchor {s['residual_l2_coef']:g}" if s.get("residual_l2_coef") else "")
                   + (f", bootstrap-at-done {s['bootstrap_at_done']}" if s.get("bootstrap_at_done", "truncated") != "truncated" else "")
                   + (", task weights " + "/".join(f"{w:g}" for w in s["task_weights"]) if s.get("task_weights") else "")
                   + (", elapsed time observed" if s.get("obs_elapsed_time") else "")
                   + (", bank at " + "/".join(map(str, s["bank_offsets"])) + " steps" if s.get("bank_offsets", [-30, -10]) != [-30, -10] else "")
                   + (", bank keeps its clock" if s.get("start_states_keep_clock") else ""))
        rows = [("the clone" if base == CLONE_NAME else "the base", r["clone"])] + [(f"{int(k):,}", v) for k, v in r["validations"].items()]
        for i, (steps, v) in enumerate(rows):
            cells = " | ".join(f"{pct(v[e]['place_success'])} [{pct(v[e]['ci95'][0])}, {pct(v[e]['ci95'][1])}]"
                               for e in TASKS)
            lines.append(f"| {r['run'] if i == 0 else ''} | {setting if i == 0 else ''} | {steps} | {cells} |")
    lines += ["", "Failures by kind (cp4: short of the goal by more than 0.10 m, turned by more than 20 degrees, "
              "dropped), the clone against each run's best validation (its worst task first, then its mean):", "",
              "| run | task | the clone | best refined (env steps) |", "|---|---|---|---|"]
    for r in runs:
        best = best_snapshot({k: {e: v["place_success"] for e, v in val.items()} for k, val in r["validations"].items()})
        for e, name in TASKS.items():
            lines.append(f"| {r['run']} | {name} | {kinds(r['clone'][e]['failures'])} | "
                         f"{kinds(r['validations'][best][e]['failures'])} ({int(best):,}) |")
    confirmed = [r for r in runs if "confirmation" in r]
    if confirmed:
        lines += ["", "Confirmation (refine.py ships a snapshot only if it wins here too): the best snapshot and the clone "
                  "again, on fresh episodes (seeds 600000 on), place %; and the agent shipped at the time on the same "
                  "episodes where refine.py measured it (it does when a snapshot beats the clone, shipping enabled):", "",
                  "| run | snapshot (env steps) | " + " | ".join(f"{t}: clone -> snapshot" for t in TASKS.values())
                  + " | beats the clone | the agent shipped then (" + " / ".join(TASKS.values()) + "): beaten |",
                  "|---|---|" + "---|" * (len(TASKS) + 2)]
        for r in confirmed:
            c = r["confirmation"]
            clone, snap = ({e: c[k][e]["place_success"] for e in TASKS} for k in ("clone", "snapshot"))
            wins = beats(snap, clone)
            then = "not measured"
            if "shipped" in c:
                shipped = {e: c["shipped"][e]["place_success"] for e in TASKS}
                then = " / ".join(pct(shipped[e]) for e in TASKS) + (": yes" if beats(snap, shipped) else ": no")
            base = Path(r["settings"].get("residual_of") or CLONE_NAME).name
            run = r["run"] + (f" (its base, {base}, in the clone's place)" if base != CLONE_NAME else "")
            lines.append(f"| {run} | {c['env_steps']:,} | "
                         + " | ".join(f"{pct(clone[e])} -> {pct(snap[e])}" for e in TASKS)
                         + f" | {'yes' if wins else 'no'} | {then} |")
    return "\n".join(lines)


def plot(runs: list[dict], out: Path) -> None:
    fig, axes = plt.subplots(1, len(TASKS), figsize=(4 * len(TASKS), 3.4), sharey=True)
    for ax, (env_id, name) in zip(axes, TASKS.items()):
        for i, r in enumerate(runs):
            steps = [0] + [int(k) for k in r["validations"]]
            success = [r["clone"][env_id]["place_success"]] + [v[env_id]["place_success"] for v in r["validations"].values()]
            ax.plot(steps, [100 * s for s in success], marker="o", color=f"C{i}", label=r["run"])
        ax.axhline(99, color="k", linestyle=":", linewidth=1)
        ax.set_title(name)
        ax.set_xlabel("PPO env steps (0: the clone)")
        ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda x, _: f"{x / 1000:g}k" if x else "0"))
    axes[0].set_ylabel("validation place success %")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)


def main(args: Args) -> str:
    runs = [load(p, args.data_dir) for p in args.runs]
    body = report(runs)
    plot(runs, args.out)
    print(body)
    if args.write_results:
        command = "python -m experiments.refine_report --runs " + " ".join(str(p) for p in args.runs) + " --write-results"
        update_section(args.results, "refinement", "\n".join([
            "## PPO refinement of the clone: validation", "", f"Command: `{command}`", "",
            "Each run of `python -m experiments.refine` (a residual policy on the frozen clone, PPO on the sparse "
            "reward at cp4): the clone and the PPO snapshots on the same validation episodes (seeds 500000 on, "
            "ordinary resets, deterministic actions).", "", body, "",
            f"![validation place success against PPO env steps]({Path(*args.out.parts[1:])})"]), "Results")
    return body


if __name__ == "__main__":
    main(tyro.cli(Args))
