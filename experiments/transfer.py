"""The from-scratch recipe on a setting it was not made for (a fourth task, a site with obstacles), from nothing or
from the weights of the shipped general agent learnt from reward alone, with no reward code of the setting's own:
the test of the dense reward's rule and of what the recipe's policy carries over (the shipped weights: the
reward-only agent PPO's recipe made, scratch_general_agent_ppo.pt). experiments/paneling.py and
experiments/obstacles.py run it (`--train nothing|shipped`) with the recipe's learner (`learner_for`): SAC from
nothing (experiments/sac_recipe.py `sac_args`, on the same envs, reward and near-goal starts), PPO from the shipped
PPO agent's weights; `--learner sac --train shipped` runs SAC from the shipped SAC agent's networks, `--learner ppo
--train nothing` PPO's recipe from nothing. Each run is
resumable in campaign/<name>/ (commit its checkpoint and CSV to go on in another session), and `steps_to` reads
from its training episodes the env steps it took to place TARGET of them."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

import numpy as np

from baselines.ppo.args import command_line
from baselines.sac import sac
from experiments.campaign import Run, checkpoint_of, checkpoint_step, describe, run_or_resume
from experiments.from_scratch import LEARNER, METHOD, csv_column, moving_mean, scratch_args, train as train_in_parts
from experiments.sac_recipe import METHOD as SAC_METHOD, run_sac, sac_args

LEARNERS = ("ppo", "sac")
"""the learners a run may take: PPO (the from-scratch recipe) or SAC (experiments/learners.py)."""
STARTS = {"nothing": None, "shipped": "assets/checkpoints/scratch_general_agent_ppo.pt"}
"""where a PPO run starts: fresh weights, or the weights of the reward-only general agent PPO's recipe made (shipped
beside SAC's, which replaced it as scratch_general_agent.pt: a PPO policy and value network, whose network PPO's recipe
shares; the imitation agent's residual network is another, SAC's has no value network)."""
SAC_STARTS = {"nothing": None, "shipped": "campaign/sac_s1/checkpoint.pt"}
"""where a SAC run starts (sac.py --init-from: actor, critics, entropy coefficient): fresh networks, or those of the
run the shipped reward-only agent comes from (the recipe's SAC seed 1) at its end, 2M env steps: the shipped file,
its snapshot at 1M, kept its actor alone (its critics, which a SAC run starts from too, were not kept then); the
run's end placed 100 / 100 / 99.9% on the test seeds (docs/data/from_scratch/sac_s1_eval50k_2000000.json)."""
TARGET = 0.9
"""the place success whose first crossing `steps_to` reports."""
STEPS_WINDOW = 50
"""iterations over which `steps_to` averages the training episodes' place success (100,000 env steps at the
recipe's 2,000 per iteration)."""
STOP_EVERY = 250_000
"""env steps between the checks of a run that stops at TARGET (`train`'s `stop_at_target`)."""
SNAPSHOT_DIR = Path("runs/transfer_snapshots")
"""where such a run's checkpoint at each check is kept (not committed)."""


@dataclass
class TrainOptions:
    """The options of a training run on a new setting: each experiment's Args takes them."""

    train: Optional[str] = None
    """train the recipe from `nothing` or from the `shipped` reward-only agent (STARTS), to the experiment's
    TRAIN_BUDGET, resuming its checkpoint; then exit."""
    train_seed: int = 1
    """with --train: the training run's seed (--seed is the first evaluation seed)."""
    learner: Optional[str] = None
    """with --train: `sac` (on the same envs, reward and starts; from the shipped weights: SAC's agent's) or `ppo` (the
    from-scratch recipe as PPO runs it; from the shipped weights: PPO's agent's); default: `learner_for` the start
    (SAC from nothing, PPO from the shipped weights, as the runs made before SAC's agent shipped)."""
    num_envs: Optional[int] = None
    """with --train: env processes (default: one per CPU core); a resumed run keeps its own."""
    evaluate: bool = False
    """with --train: evaluate that run's policy, the experiment's way, instead of training."""
    dry_run: bool = False
    """with --train: print the plan and where the run stands, and exit."""


def learner_for(start: str, learner: Optional[str] = None) -> str:
    """`learner`, checked, or the default for `start`: the recipe's learner (experiments/from_scratch.py LEARNER)
    from nothing; PPO from the shipped weights (the runs from them began before SAC's agent shipped: `--learner sac`
    starts SAC from SAC's)."""
    if start not in STARTS:
        raise SystemExit(f"--train {start}: use one of {', '.join(STARTS)}")
    if learner is None:
        return LEARNER if STARTS[start] is None else "ppo"
    if learner not in LEARNERS:
        raise SystemExit(f"--learner {learner}: use one of {', '.join(LEARNERS)}")
    return learner


def start_name(start: str, learner: Optional[str] = None) -> str:
    """How the tables name a run's learner and start: "SAC from nothing", "SAC from SAC's agent" (SAC_STARTS),
    "PPO from PPO's agent" (STARTS), ..."""
    learner = learner_for(start, learner).upper()
    return f"{learner} from " + ("nothing" if start == "nothing" else f"{learner}'s agent")


def transfer_run(name: str, start: str, seed: int, num_envs: Optional[int], budget: int, command: str, what: str,
                 learner: Optional[str] = None, **setting) -> Run:
    """The recipe (experiments/from_scratch.py's `scratch_args`) from `start` (STARTS) to `budget` env steps on
    seed `seed`, unchanged but for the `setting` (Args fields of both learners: an env, a scene), in
    campaign/<name>_<start>_s<seed>/; with `learner` "sac", SAC's (experiments/sac_recipe.py `sac_args`) from
    SAC_STARTS[start], in campaign/<name>_sac_s<seed>/ (from nothing) or <name>_shipped_sac_s<seed>/ (`learner` None:
    `learner_for` the start). Its command names the learner, but for PPO from the shipped weights (the default
    there)."""
    learner = learner_for(start, learner)
    if learner == "sac":
        init = SAC_STARTS[start]
        exp_name = f"{name}_sac_s{seed}" if init is None else f"{name}_{start}_sac_s{seed}"
        args = sac_args(seed, exp_name=exp_name, total_timesteps=budget, init_from=init,
                        **({"num_envs": num_envs} if num_envs else {}), **setting)
        how = "from nothing" if init is None else f"from the weights of {init}"
        return Run(exp_name, args, f"SAC on {what} {how}, seed {seed}",
                   f"{command} --train {start} --learner sac --train-seed {seed}", None,
                   method=SAC_METHOD if init is None else SAC_METHOD.replace("SAC from nothing", f"SAC from {init}"))
    exp_name = f"{name}_{start}_s{seed}"
    args = scratch_args(num_envs, seed=seed, exp_name=exp_name, total_timesteps=budget, checkpoint=STARTS[start], **setting)
    how = "from nothing" if STARTS[start] is None else f"from the weights of {STARTS[start]}"
    return Run(exp_name, args, f"the from-scratch recipe on {what} {how}, seed {seed}",
               f"{command} --train {start} --train-seed {seed}"
               + ("" if learner_for(start) == "ppo" else " --learner ppo"), None, method=METHOD)


def steps_to(progress: Path, target: float = TARGET, window: int = STEPS_WINDOW) -> Optional[int]:
    """The first env step at which the training episodes from ordinary resets placed at least `target` (their mean
    over the last `window` iterations: 100,000 env steps at the recipe's 2,000 per iteration); None if never."""
    with open(progress, newline="") as f:
        rows = list(csv.DictReader(f))
    placed = moving_mean(csv_column(rows, "ordinary_place_success"), window)
    hit = np.flatnonzero(np.nan_to_num(placed) >= target)
    return int(csv_column(rows, "global_step")[hit[0]]) if len(hit) else None


def samples_per_row(run: Run) -> int:
    """env steps between two rows of the run's progress.csv (what `campaign.training_wall_s` divides by each sps)."""
    return run.args.log_freq if isinstance(run.args, sac.Args) else run.args.num_envs * run.args.num_steps


def train(run: Run, dry_run: bool = False, stop_at_target: bool = False,
          snapshots: Optional[tuple[int, Callable[[int, Path], None]]] = None, until: int = 0) -> None:
    """Print the plan and where `run` stands; unless `dry_run`, train (or resume) it to its budget and say when its
    training episodes first placed TARGET. With `stop_at_target` it trains in parts of STOP_EVERY env steps and ends
    after the first part by whose end they have: what such an experiment measures (`steps_to`) is known then, and
    the rest of the budget would only train past it. With `snapshots` = (every, keep) (SAC), its parts are `every`
    env steps (a divisor of STOP_EVERY: it still stops at a STOP_EVERY mark), `keep(env steps, checkpoint)` called at
    each part's end. With `until` (SAC), it stops at no mark before `until` env steps: a run that reached its target
    goes on to see whether what it measures stays."""
    if until and (until % STOP_EVERY or until > run.args.total_timesteps):
        raise SystemExit(f"--until {until:,}: a multiple of {STOP_EVERY:,} env steps, at most the run's budget "
                         f"({run.args.total_timesteps:,})")
    progress = checkpoint_of(run).parent / "progress.csv"
    print(describe(run))
    if not isinstance(run.args, sac.Args):
        print("as one ppo.py command: python baselines/ppo/ppo.py " + " ".join(command_line(run.args)))
    if stop_at_target:
        print(f"it stops at the first {STOP_EVERY:,}-env-step mark" + (f" from {until:,} on" if until else "")
              + f" by which its training episodes placed >= {TARGET:.0%}")
    if dry_run:
        return
    reached = lambda: progress.is_file() and steps_to(progress) is not None  # noqa: E731
    if isinstance(run.args, sac.Args):
        every, keep = snapshots or (STOP_EVERY if stop_at_target else None, None)
        if every is not None and STOP_EVERY % every:
            raise ValueError(f"snapshots every {every:,} env steps: use a divisor of {STOP_EVERY:,}")
        at_mark = lambda: (step := checkpoint_step(checkpoint_of(run))) % STOP_EVERY == 0 and step >= until  # noqa: E731
        run_sac(run.args, every=every, stop=(lambda: at_mark() and reached()) if stop_at_target else None,
                after_part=keep)
    elif not stop_at_target:
        run_or_resume(run)
    else:
        train_in_parts(run, SNAPSHOT_DIR / run.name, every=STOP_EVERY, stop=reached)
    reached = steps_to(progress)
    print(f"{run.name}: training episodes placed >= {TARGET:.0%} "
          + (f"from {reached:,} env steps" if reached is not None else "not yet"))


def plot_training(panels: dict[str, dict[str, tuple[np.ndarray, np.ndarray]]], out: Path, title: str,
                  collided: Optional[dict[str, dict[str, tuple[np.ndarray, np.ndarray]]]] = None) -> None:
    """One panel per key of `panels` (its title; "" for none): each run's training episodes placed from ordinary
    resets (steps, their moving mean) against env steps, and the TARGET line; with `collided` (the same keys), a
    second row of panels: the share of those episodes that touched an obstacle, for the runs that logged it. A run
    keeps its colour and line in every panel; the legend below the panels."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [("training episodes placed, %\n(ordinary resets, cp4)", panels)]
    if collided is not None:
        rows.append(("of them touched an obstacle, %", collided))
    runs = list(dict.fromkeys(label for curves in panels.values() for label in curves))
    # matplotlib's ten colours, dashed from the eleventh run on, so that no two runs look alike
    style = {label: dict(color=f"C{i % 10}", ls="-" if i < 10 else "--") for i, label in enumerate(runs)}
    fig, axes = plt.subplots(len(rows), len(panels), sharex="col", sharey="row", squeeze=False,
                             figsize=(7 if len(panels) == 1 else 3.6 * len(panels), 1.2 + 3.0 * len(rows)))
    for r, (ylabel, grid) in enumerate(rows):
        for ax, (panel, curves) in zip(axes[r], grid.items()):
            for label, (steps, share) in curves.items():
                ax.plot(steps / 1e6, 100 * share, label=label, **style[label])
            if r == 0:
                ax.axhline(100 * TARGET, color="gray", ls="--", lw=1)
                if panel:
                    ax.set_title(panel, fontsize=9)
            ax.set_ylim(0, 102)
        axes[r][0].set_ylabel(ylabel)
    for ax in axes[-1]:
        ax.set_xlabel("env steps (millions)")
    handles, labels = axes[0][0].get_legend_handles_labels()
    ncol = 1 if len(panels) == 1 else min(2, len(labels))  # one narrow panel: long labels one to a line
    fig.legend(handles, labels, fontsize=7, loc="lower center", ncol=ncol)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0, 0.045 * (-(-len(labels) // ncol) + 1) / len(rows), 1, 1))
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100)
    plt.close(fig)
