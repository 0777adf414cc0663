"""Openings no agent trained on (issue 53, part 2): the from-scratch recipe with one goal opening of every task type
held out of training, evaluated with the paper's protocol on the openings it never saw and on those it trained on.

    python -m experiments.unseen_openings --seed 1 --dry-run     # the plan, and where that seed's run stands
    python -m experiments.unseen_openings --seed 1               # train (or resume) the recipe (SAC), to 90% placed
    python -m experiments.unseen_openings --seed 2 --until 500000    # on past that, to 500,000 env steps
    python -m experiments.unseen_openings --seed 1 --evaluate    # the paper's protocol, unseen and seen openings
    python -m experiments.unseen_openings --seed 1 --learner ppo # PPO's recipe instead, to its budget
    python -m experiments.unseen_openings --imitation --dry-run  # its plan, and how far it has come
    python -m experiments.unseen_openings --imitation            # the imitation twin: demonstrations -> clone ->
                                                                 # residual PPO on the trained openings; the clone and
                                                                 # the refined policy evaluated
    python -m experiments.unseen_openings --seed 1 --curve       # the held-out and trained openings placed at each
                                                                 # snapshot the run kept (30 episodes per task)
    python -m experiments.unseen_openings --expert               # the planning expert on the same openings
    python -m experiments.unseen_openings --report               # RESULTS' section from the evaluations

The recipe is experiments/from_scratch.py's, unchanged, but for the goal openings its training envs draw (HELD_OUT
never); its evaluations during training draw every opening. Held out: the
middle opening of every task type. The window openings at y = -0.85 and +0.85 are each other's mirror image, which
the recipe's policy meets as one (`mirror_twins`): only the middle one is unseen in every form.

Its learner is the recipe's, SAC (experiments/sac_recipe.py `sac_args`, its training envs drawing TRAINED only:
`goal_slots`), in parts of 250,000 env steps to at most sac_recipe.BUDGET, ending at the first mark by which its
training episodes placed 90% (experiments/transfer.py `steps_to`), as the runs on paneling do, its checkpoint kept
every CURVE_EVERY env steps (runs/unseen_snapshots/<run>/, not committed) for the curve (`--curve`): what carries over
to an opening never trained on comes and goes as the policy trains (seed 1's floor panels: 96.7% placed at the
middle recess at 328,578 env steps, none at 500,000). With `--learner ppo`, PPO's recipe (`--goal-slot-weights`) to
its budget.

The imitation twin (`--imitation`) is the shipped imitation agent's recipe, its two commands as their records name
them (IMITATION_CLONE: experiments/general_agent.py's direct-path demonstrations and behaviour clone;
IMITATION_REFINE: experiments/refine.py's residual PPO on the frozen clone), with `goal_slots` = TRAINED in both:
no demonstration, takeover, bank state, training episode, validation or confirmation draws a held-out opening. Its
stages write to runs/unseen_imitation/ and each is skipped when its output is there (demonstrations of about 100 MB
are not committed; about 3 h on 2 cores, measured). The clone is committed (KEPT_CLONE): on another machine the twin
starts from it, at the refinement (about 1.8 h, most of it validation).
"""

from __future__ import annotations

import json
import shlex
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import tyro

from baselines.ppo import evaluation
from baselines.ppo.args import command_line
from baselines.ppo.evaluation import pct, training_slot_weights, wilson
from baselines.ppo.start_states import GOAL_SLOTS
from experiments import sac_recipe, transfer
from experiments.campaign import (Run, checkpoint_of, checkpoint_step, describe, record_checkpoint_step,
                                 run_or_resume)
from experiments.from_scratch import LEARNER, LEARNERS, METHOD, scratch_args
from ms_construction.assets import sha256
from ms_construction.envs import PAPER_TASK_ENV_IDS
from ms_construction.reporting import update_section

HELD_OUT = (1,)
"""the goal openings (slot indices, every task type) training never draws."""
TRAINED = tuple(s for s in range(GOAL_SLOTS) if s not in HELD_OUT)
COMMAND = "python -m experiments.unseen_openings"
EVAL_DIR = Path("docs/data/unseen_openings")
EVAL_STEPS = 50_000
"""env steps per task and set of openings: the paper's protocol."""
EXPERT_EPISODES = 60
"""test seeds per task and set of openings the planning expert runs (`--expert`): it plans for whatever goal it meets,
so it has no trained and held-out openings, only the same two sets to compare with."""


def seed_run(seed: int, num_envs: Optional[int] = None) -> Run:
    """The recipe from nothing on `seed`, its training envs never drawing the HELD_OUT openings."""
    name = f"unseen_s{seed}"
    return Run(name, scratch_args(num_envs, seed=seed, exp_name=name, goal_slot_weights=training_slot_weights(TRAINED)),
               f"PPO's recipe from nothing, seed {seed}, goal openings {', '.join(map(str, HELD_OUT))} held out",
               f"{COMMAND} --seed {seed} --learner ppo", None, method=METHOD)


def sac_run(seed: int) -> Run:
    """SAC from nothing on `seed` (experiments/sac_recipe.py), its training envs never drawing the HELD_OUT openings."""
    name = f"unseen_sac_s{seed}"
    return Run(name, sac_recipe.sac_args(seed, exp_name=name, goal_slots=TRAINED),
               f"SAC from nothing, seed {seed}, goal openings {', '.join(map(str, HELD_OUT))} held out",
               f"{COMMAND} --seed {seed} --learner sac", None, method=sac_recipe.METHOD)


IMITATION_DIR = Path("runs/unseen_imitation")
IMITATION_CLONE = dict(branch_preference="fixed", demo_pace="fast", direct_paths=True, window_takeovers=(),
                       flooring_takeovers=(), ceiling_takeovers=())
"""experiments/general_agent.py's settings of the shipped clone (general_agent_clone_direct.pt's record)."""
IMITATION_REFINE = dict(reward_mode="sparse", reward_scale=1.0, gamma=0.999, bootstrap_at_done="truncated",
                        task_weights=(0.5, 0.25, 0.25), bank_episodes=3000, bank_offsets=(-40, -25, -10),
                        validation_episodes=1000, confirmation_episodes=1000, total_timesteps=600_000)
"""experiments/refine.py's settings of the shipped imitation agent (general_agent.pt's record)."""
KEPT_CLONE = Path("campaign/unseen_imitation/clone.pt")
"""the twin's clone, committed: on a machine whose run directory holds no clone of its own the twin refines this one
instead of recording the demonstrations (68 minutes) and cloning them again."""


SNAPSHOT_DIR = Path("runs/unseen_snapshots")
"""a SAC run's checkpoint at every CURVE_EVERY env steps: <SNAPSHOT_DIR>/<run>/checkpoint_<env steps>.pt."""
CURVE_EVERY = 50_000
"""env steps between the kept snapshots (the run's checkpoint interval, where its episodes restart anyway)."""
CURVE_EPISODES = 30
"""episodes per task and set of openings that measure a snapshot for the curve."""
CURVE_SEED = 500_000
"""the curve's first seed: validation seeds (the paper's protocol keeps the test seeds, from 1,000,000)."""
CURVE_PLOT = Path("docs/images/unseen_openings_curve.png")


def keep_snapshot(run: Run, step: int, checkpoint: Path) -> None:
    """The run's checkpoint at `step` env steps copied to its snapshots (`transfer.train`'s `keep`)."""
    out = SNAPSHOT_DIR / run.name / f"checkpoint_{step}.pt"
    out.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(checkpoint, out)


def curve_json(seed: int, step: int, seen: bool) -> Path:
    """A SAC seed's snapshot at `step` env steps on the held-out or the trained openings (CURVE_EPISODES per task)."""
    return EVAL_DIR / "curve" / f"unseen_sac_s{seed}_{step}_{'seen' if seen else 'unseen'}.json"


def evaluate_curve(seed: int, workers: int = 2) -> dict[int, dict[bool, Path]]:
    """Each snapshot the SAC seed's run kept, measured on the held-out and the trained openings (CURVE_EPISODES per
    task from CURVE_SEED), each JSON written once; env steps -> {seen: JSON} of every snapshot measured so far."""
    for path in sorted((SNAPSHOT_DIR / sac_run(seed).name).glob("checkpoint_*.pt"),
                       key=lambda p: int(p.stem.split("_")[1])):
        step = checkpoint_step(path)
        for seen, slots in ((False, HELD_OUT), (True, TRAINED)):
            out = curve_json(seed, step, seen)
            if not out.is_file():
                evaluation.main(evaluation.Args(checkpoint=path, all=True, episodes=CURVE_EPISODES, seed=CURVE_SEED,
                                                goal_slots=slots, workers=workers, json=out))
                record_checkpoint_step(out, path)
    return curve_points(seed)


def curve_points(seed: int) -> dict[int, dict[bool, Path]]:
    """env steps -> {seen: JSON} of the seed's snapshots measured for the curve."""
    points: dict[int, dict[bool, Path]] = {}
    for path in (EVAL_DIR / "curve").glob(f"unseen_sac_s{seed}_*.json"):
        step, which = path.stem.removeprefix(f"unseen_sac_s{seed}_").split("_")
        points.setdefault(int(step), {})[which == "seen"] = path
    return dict(sorted(points.items()))


def plot_curve(out: Optional[Path] = None) -> Optional[Path]:
    """Per task type, each SAC seed's snapshots placed on the held-out openings (solid) and the trained ones (dashed)
    against env steps, to `out` (default CURVE_PLOT); None where no snapshot is measured."""
    out = out or CURVE_PLOT
    curves = {seed: curve_points(seed) for seed in SEEDS}
    if not any(curves.values()):
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(PAPER_TASK_ENV_IDS), figsize=(11, 3.4), sharey=True)
    for ax, (kind, env) in zip(axes, PAPER_TASK_ENV_IDS.items()):
        for (seed, points), color in zip(curves.items(), ("tab:blue", "tab:red")):
            for seen, style in ((False, "-"), (True, "--")):
                xs = [step for step, p in points.items() if seen in p]
                ys = [100 * json.loads(points[x][seen].read_text())["tasks"][env]["place_success"] for x in xs]
                if xs:
                    ax.plot([x / 1e6 for x in xs], ys, style, marker="o", ms=3, color=color,
                            label=f"seed {seed}, {'trained' if seen else 'held-out'} openings")
        ax.set_title(kind)
        ax.set_xlabel("env steps (millions)")
        ax.set_ylim(-2, 102)
    axes[0].set_ylabel(f"placed, % of {CURVE_EPISODES} episodes")
    axes[-1].legend(fontsize=7, loc="center right")
    fig.suptitle("SAC from nothing with the middle opening of every task held out", fontsize=10)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100)
    plt.close(fig)
    return out


def evaluation_json(seed, seen: bool) -> Path:
    """A run's evaluation on the unseen or the seen openings: `seed` is the recipe's seed, "sac_s<seed>" or
    one of IMITATION_POLICIES."""
    return EVAL_DIR / f"unseen_{'s' if isinstance(seed, int) else ''}{seed}_{'seen' if seen else 'unseen'}.json"


def expert_json(seen: bool) -> Path:
    """The planning expert's episodes on the held-out or the trained openings (`evaluate_expert`)."""
    return EVAL_DIR / f"unseen_expert_{'seen' if seen else 'unseen'}.json"


def evaluate_expert(episodes: int = EXPERT_EPISODES, workers: int = 2) -> None:
    """The planning expert (scripts/run_expert.py) on `episodes` test seeds per task drawing the held-out openings
    only, then the trained ones only, cp4; each JSON in the shape of an agent's evaluation (`tasks`), written once
    per number of episodes."""
    from scripts import run_expert

    for seen, slots in ((False, HELD_OUT), (True, TRAINED)):
        out = expert_json(seen)
        if out.is_file() and json.loads(out.read_text())["episodes_per_task"] == episodes:
            continue
        args = run_expert.Args(episodes=episodes, seed=evaluation.Args.seed, goal_slots=slots, workers=workers)
        episodes_of = {env_id: run_expert.run_env(args, env_id) for env_id in PAPER_TASK_ENV_IDS.values()}
        tasks = {env_id: {**run_expert.summarize(results),
                          "place_success_ci95": wilson(sum(r["placed"] for r in results), len(results))}
                 for env_id, results in episodes_of.items()}
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps({"command": f"{COMMAND} --expert", "goal_slots": slots, "seed": args.seed,
                                   "episodes_per_task": episodes, "tasks": tasks, "episodes": episodes_of},
                                  indent=0) + "\n")


def earlier_json(latest: Path, step: int) -> Path:
    """Where a run's evaluation at `step` goes once a later one of the same run takes `latest`'s place."""
    return latest.with_name(f"{latest.stem}_{step}.json")


def evaluations_of(seed, seen: bool) -> list[dict]:
    """A run's evaluations on the unseen or the seen openings, the earlier ones (`earlier_json`) then the latest."""
    latest = evaluation_json(seed, seen)
    paths = sorted(latest.parent.glob(f"{latest.stem}_*.json"), key=lambda p: int(p.stem.rsplit("_", 1)[1]))
    return [json.loads(p.read_text()) for p in [*paths, latest] if p.is_file()]


def evaluate(checkpoint: Path, seed, steps: int = EVAL_STEPS, workers: int = 2) -> None:
    """The paper's protocol (test seeds, `steps` per task, cp4) on the held-out openings, then on the trained ones;
    each JSON records the env steps the checkpoint had trained (`checkpoint_step`) where the checkpoint says. An
    evaluation of the run at other env steps is kept beside it (`earlier_json`)."""
    for seen, slots in ((False, HELD_OUT), (True, TRAINED)):
        out = evaluation_json(seed, seen)
        if out.is_file() and (before := json.loads(out.read_text()).get("checkpoint_step")) is not None \
                and before != checkpoint_step(checkpoint):
            out.rename(earlier_json(out, before))
        evaluation.main(evaluation.Args(checkpoint=checkpoint, all=True, steps=steps, goal_slots=slots,
                                        workers=workers, json=out))
        record_checkpoint_step(out, checkpoint)


def evaluated(checkpoint: Path, seed) -> bool:
    """Whether both of `seed`'s evaluations are of `checkpoint` as it is (naming it, and the file's sha256 theirs): the
    twin's rerun does not evaluate its policies again, on a fresh clone too. An evaluation written before the JSON
    recorded the hash counts where it is newer than the file (file times: on a fresh clone, checkout times)."""
    digest = sha256(checkpoint) if Path(checkpoint).is_file() else None

    def of_it(out: Path) -> bool:
        data = json.loads(out.read_text())
        if data.get("checkpoint") != str(checkpoint):
            return False
        if "checkpoint_sha256" in data:
            return data["checkpoint_sha256"] == digest
        return out.stat().st_mtime > Path(checkpoint).stat().st_mtime

    return all(out.is_file() and of_it(out) for out in (evaluation_json(seed, seen) for seen in (False, True)))


def refines_kept_clone(run_dir: Path) -> bool:
    """Whether the twin in `run_dir` refines the committed clone (KEPT_CLONE): it has no clone of its own."""
    return KEPT_CLONE.is_file() and not (run_dir / "clone").is_dir()


def imitation(run_dir: Optional[Path] = None, clone: Optional[dict] = None,
              refine_args: Optional[dict] = None) -> tuple[Path, Path]:
    """The imitation twin, stage by stage (each skipped where its output is there): the clone of the expert's
    demonstrations of the TRAINED openings, its residual PPO refinement on them, the refined policy chosen on
    validation among them; the clone and the refined policy. `clone`, `refine_args`: overrides of IMITATION_CLONE,
    IMITATION_REFINE. `run_dir`: default IMITATION_DIR."""
    from experiments import general_agent, refine

    run_dir = run_dir or IMITATION_DIR
    if refines_kept_clone(run_dir):
        cloned = KEPT_CLONE  # another machine made it: its demonstrations are not committed
    else:
        cloned = general_agent.main(general_agent.Args(run_dir=run_dir / "clone", goal_slots=TRAINED,
                                                       **{**IMITATION_CLONE, **(clone or {})}))
    return cloned, refine.main(refine.Args(clone=cloned, run_dir=run_dir / "refine", goal_slots=TRAINED, ship=False,
                                           **{**IMITATION_REFINE, **(refine_args or {})}))


def imitation_plan(run_dir: Optional[Path] = None) -> str:
    """What `imitation` would do, and how far it has come in `run_dir` (default IMITATION_DIR; nothing is run)."""
    run_dir = run_dir or IMITATION_DIR
    lines = [f"the imitation twin on goal openings {', '.join(map(str, TRAINED))} "
             f"(held out: {', '.join(map(str, HELD_OUT))}), in {run_dir}:"]
    for stage, what, settings in (
            ("clone", "the expert's demonstrations and their behaviour clone (experiments/general_agent.py)", IMITATION_CLONE),
            ("refine", "residual PPO on the frozen clone, chosen on validation (experiments/refine.py)", IMITATION_REFINE)):
        where = run_dir / stage
        made = sum(p.is_file() for p in where.rglob("*")) if where.is_dir() else 0
        kept = stage == "clone" and refines_kept_clone(run_dir)
        lines.append(f"- {stage}: {what}, {settings}: " + (f"{made} file{'s' * (made != 1)} in {where} so far" if made
                                                          else f"the committed one, {KEPT_CLONE}" if kept else "not started"))
    for policy in IMITATION_POLICIES:
        for seen in (False, True):
            path = evaluation_json(policy, seen)
            lines.append(f"- the paper's protocol, {run_label(policy)}, on the {'trained' if seen else 'held-out'} "
                         "openings: " + (f"done ({path})" if path.is_file() else "not yet"))
    return "\n".join(lines)


SEEDS = (1, 2)
IMITATION_POLICIES = ("imitation_clone", "imitation")
"""the imitation twin's two policies as `evaluation_json` names them: its clone, then the clone refined by PPO (the
recipe's policy). The clone alone says what the demonstrations carry to an opening they never showed; the refined
policy, what PPO on the trained openings adds or takes away."""
EVALUATED = (*SEEDS, *(f"sac_s{s}" for s in SEEDS), *IMITATION_POLICIES)
"""the runs whose evaluations the report looks for (`evaluation_json`'s `seed`): the recipe's seeds, SAC's, the
imitation twin's policies."""


def learner_and_seed(seed) -> tuple[str, Optional[int]]:
    """The learner (and its start) of `evaluation_json`'s `seed`, and the training seed (None: the imitation
    twin's one run)."""
    if isinstance(seed, int):
        return "PPO from nothing", seed
    if seed.startswith("sac_s"):
        return "SAC from nothing", int(seed.removeprefix("sac_s"))
    return ("imitation: its clone alone" if seed == "imitation_clone" else "imitation (clone + residual PPO)"), None


def run_label(seed) -> str:
    """How RESULTS names the run of `evaluation_json`'s `seed`."""
    learner, number = learner_and_seed(seed)
    return learner if number is None else f"{learner}, seed {number}"


def trained_steps(seed, data: dict) -> str:
    """The table's env steps of an evaluated run: its RL's (an imitation policy's PPO on the clone, the expert's
    demonstrations not counted: the clone's own record counts them)."""
    if "checkpoint_step" not in data:
        return "-"
    step = data["checkpoint_step"]
    if isinstance(seed, str) and seed.startswith("imitation"):
        return f"{step:,} of PPO on the clone" if step else "none: demonstrations only"
    return f"{step:,}"


def report(results: Path = Path("docs/RESULTS.md")) -> str:
    """RESULTS' section: per run evaluated (EVALUATED), place success on the unseen and the seen openings per task."""
    lines = ["| run | its env steps | openings | " + " | ".join(f"{k}: placed % [95% CI]" for k in PAPER_TASK_ENV_IDS)
             + " |", "|---|---|---|" + "---|" * len(PAPER_TASK_ENV_IDS)]

    def cells(tasks: dict) -> str:
        return " | ".join(pct(tasks[e]["place_success"], tasks[e]["place_success_ci95"]) for e in PAPER_TASK_ENV_IDS.values())

    def openings(seen: bool) -> str:
        return f"{'trained on' if seen else 'never trained on'} ({', '.join(map(str, TRAINED if seen else HELD_OUT))})"

    for seen in (False, True):
        if (path := expert_json(seen)).is_file():
            data = json.loads(path.read_text())
            lines.append(f"| planning expert | none: it plans each episode ({data['episodes_per_task']} per task) | "
                         f"{openings(seen)} | {cells(data['tasks'])} |")
    for seed in EVALUATED:
        rows = [(d.get("checkpoint_step", 0), seen, d) for seen in (False, True) for d in evaluations_of(seed, seen)]
        for _, seen, data in sorted(rows, key=lambda r: r[:2]):  # a row per evaluation, in order of env steps
            lines.append(f"| {run_label(seed)} | {trained_steps(seed, data)} | {openings(seen)} | {cells(data['tasks'])} |")
    table = "\n".join(lines) if len(lines) > 2 else "No run has been evaluated yet."
    body = ("## Openings no agent trained on\n\n"
            f"Commands: `{COMMAND} --seed S` (training SAC; `--learner ppo`: PPO's recipe), `{COMMAND} --seed S "
            f"--evaluate`, `{COMMAND} --imitation`, `{COMMAND} --expert`, `{COMMAND} --report`. The from-scratch recipe, SAC and "
            "the imitation recipe, their training never drawing the held-out goal opening of any task type; the "
            f"paper's protocol ({EVAL_STEPS:,} env steps per task, cp4, test seeds) on each set of openings; the "
            "planning expert, which plans for whatever goal it meets, on test seeds drawing each set alone.\n\n"
            f"{table}\n")
    if any(curve_points(seed) for seed in SEEDS):
        body += (f"\n![the openings over training]({CURVE_PLOT.relative_to('docs')})\n\n*Made by `{COMMAND} --seed S "
                 f"--curve`: each snapshot the SAC run kept (every {CURVE_EVERY:,} env steps) on {CURVE_EPISODES} "
                 f"episodes per task from seed {CURVE_SEED:,} (validation seeds), on the held-out openings (solid) and "
                 "the trained ones (dashed).*\n")
    update_section(results, "unseen-openings", title="Results", body=body)
    return body


@dataclass
class Args:
    seed: Optional[int] = None
    """the run's seed (campaign/unseen_s<seed>/)."""
    num_envs: Optional[int] = None
    """env processes (default: one per CPU core); a resumed run keeps its own."""
    dry_run: bool = False
    """print the plan and where the run stands, and exit."""
    evaluate: bool = False
    """evaluate the seed's run (the paper's protocol on unseen and seen openings), and exit."""
    report: bool = False
    """write RESULTS' section from the evaluations there are, and exit."""
    expert: bool = False
    """run the planning expert on EXPERT_EPISODES test seeds per task of the held-out openings and of the trained ones
    (`evaluate_expert`), write RESULTS' section, and exit."""
    imitation: bool = False
    """run (or resume) the imitation twin (`imitation`) and evaluate its clone and its refined policy, then exit."""
    learner: str = LEARNER
    """with --seed: `sac` (the recipe's learner: `sac_run`) or `ppo` (PPO's recipe: `seed_run`)."""
    until: Optional[int] = None
    """with --seed (SAC): go on past the first mark by which its training episodes placed 90%, to this many env steps
    (a multiple of 250,000): whether what carries over stays (seed 1's floor panels did not)."""
    curve: bool = False
    """with --seed (SAC): measure each snapshot its run kept on the held-out and the trained openings
    (`evaluate_curve`), plot every seed's (CURVE_PLOT), and exit."""


def main(args: Args) -> None:
    if args.report:
        print(report())
        return
    if args.expert:
        evaluate_expert()
        print(report())
        return
    if args.imitation:
        print(imitation_plan())
        if args.dry_run:
            return
        for policy, name in zip(imitation(), IMITATION_POLICIES):
            if not evaluated(policy, name):
                evaluate(policy, name)
        print(report())
        return
    if args.seed is None:
        raise SystemExit("give --seed S (to train, or --evaluate its run), --imitation or --report")
    if args.learner not in LEARNERS:
        raise SystemExit(f"--learner {args.learner}: use one of {', '.join(LEARNERS)}")
    if args.learner == "sac":
        run = sac_run(args.seed)
        if args.evaluate:
            evaluate(checkpoint_of(run), f"sac_s{args.seed}")
        elif args.curve:
            evaluate_curve(args.seed)
            print(f"wrote {plot_curve()}")
        else:
            transfer.train(run, args.dry_run, stop_at_target=True, until=args.until or 0,
                           snapshots=(CURVE_EVERY, lambda step, ckpt: keep_snapshot(run, step, ckpt)))
        return
    run = seed_run(args.seed, args.num_envs)
    print(describe(run))
    print("as one ppo.py command: python baselines/ppo/ppo.py " + shlex.join(command_line(run.args)))
    if args.evaluate:
        evaluate(checkpoint_of(run), args.seed)
    elif not args.dry_run:
        run_or_resume(run)


if __name__ == "__main__":
    main(tyro.cli(Args))
