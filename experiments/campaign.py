"""A campaign of training runs that spans sessions: each run resumes from its checkpoint in campaign/ (commit
that and its progress.csv between sessions), and a run that has reached the end of its plan ships its final
policy to assets/checkpoints/ with its campaign record. The paper's experiment (experiments/paper.py) and the
general agent from reward alone (experiments/from_scratch.py) are campaigns."""

from __future__ import annotations

import csv
import json
import os
import platform
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import torch

from baselines.ppo import ppo
from baselines.ppo.args import Args
from baselines.ppo.checkpoints import load_checkpoint
from baselines.sac import sac

CAMPAIGN_DIR = Path("campaign")
"""where the campaign's runs live; their latest checkpoint and progress CSV are committed."""
SHIPPED_DIR = Path("assets/checkpoints")
"""where a finished run's final policy is shipped (`ship`)."""


@dataclass
class Run:
    """One run of the campaign: its name, its ppo.py (or sac.py) Args, what it is, the command that runs it, and
    where its final policy is shipped when it has run to the end of its plan (None: not shipped)."""

    name: str
    args: Args | sac.Args
    what: str
    command: str
    shipped: Optional[Path] = None
    method: Optional[str] = None
    """the campaign record's method line (default: the paper setting's)."""


def choose(runs: list[Run], names: tuple[str, ...]) -> list[Run]:
    """The runs named `names`, in that order; an unknown name stops with the names allowed (`--runs`)."""
    plan = {r.name: r for r in runs}
    unknown = [n for n in names if n not in plan]
    if unknown:
        raise SystemExit(f"--runs {' '.join(unknown)}: use among {', '.join(plan)}")
    return [plan[n] for n in names]


def checkpoint_of(run: Run) -> Path:
    return args_checkpoint(run.args)


def args_checkpoint(a: Args | sac.Args) -> Path:
    """Where a PPO or SAC run's Args keep its latest checkpoint (both learners write it there)."""
    return Path(a.log_dir) / a.exp_name / "checkpoint.pt"


def checkpoint_step(checkpoint: Path) -> Optional[int]:
    """The env steps a PPO or SAC checkpoint had trained (its progress' global_step); None where it records none (an
    agent shipped without its clock)."""
    step = torch.load(checkpoint, map_location="cpu", weights_only=False).get("progress", {}).get("global_step")
    return None if step is None else int(step)


def record_checkpoint_step(evaluation_json: Path, checkpoint: Path) -> None:
    """Write into an evaluation's JSON the env steps its checkpoint had trained (`checkpoint_step`), where the
    checkpoint says: a run's latest checkpoint moves on after it is evaluated."""
    if (step := checkpoint_step(checkpoint)) is not None:
        data = json.loads(evaluation_json.read_text())
        evaluation_json.write_text(json.dumps(dict(data, checkpoint_step=step), indent=1) + "\n")


def describe(run: Run) -> str:
    """One line: the run, its budget and stages (PPO's), and where it stands."""
    a, ckpt = run.args, checkpoint_of(run)
    done = checkpoint_step(ckpt) if ckpt.is_file() else 0
    if isinstance(a, sac.Args):
        stages = (f", stages {' '.join(a.curriculum)} ({a.stage_timesteps:,} env steps each)"
                  if len(a.curriculum) > 1 else "")
        return (f"{run.name}: {run.what}; {a.env_id}{stages}, {a.total_timesteps:,} env steps, seed {a.seed}, "
                f"{a.num_envs} envs; "
                f"{'resumes at step ' + format(done, ',') if done else 'starts fresh'} ({ckpt})")
    return (f"{run.name}: {run.what}; {a.env_id}, stages {' '.join(a.stages.curriculum)} ({a.stages.stage_timesteps:,} steps each), "
            f"{a.total_timesteps:,} steps, curiosity {a.icm.curiosity}, seed {a.seed}, {a.num_envs} envs x {a.num_steps} steps "
            f"per update; {'resumes at step ' + format(done, ',') if done else 'starts fresh'} ({ckpt})"
            + (f"; ships to {run.shipped}" if run.shipped else ""))


def run_or_resume(run: Run) -> None:
    """Train `run` to the end of its budget, resuming its checkpoint if it has one, and ship its final
    policy (`ship`). A run that was planned with a larger budget than its checkpoint's (control groups
    from 2M to 8M) continues to it."""
    ckpt = checkpoint_of(run)
    ppo.main(run.args.replace(resume=str(ckpt), extend=True) if ckpt.is_file() else run.args)
    if run.shipped is not None:
        ship(run)


def training_wall_s(progress_csv: Path, samples_per_iteration: int, until_step: Optional[int] = None) -> float:
    """The wall time of a run's training iterations (rollouts and updates) from its progress.csv (up to `until_step`
    when given): evaluations, start-ups and the time between sessions are not in it. A PPO row is an iteration of
    `samples_per_iteration` env steps at its sps; a SAC row carries its run's env and update seconds so far."""
    with open(progress_csv, newline="") as f:
        rows = [row for row in csv.DictReader(f) if until_step is None or int(row["global_step"]) <= until_step]
    if rows and "update_s" in rows[0]:
        return float(rows[-1]["env_s"]) + float(rows[-1]["update_s"])
    return sum(samples_per_iteration / float(row["sps"]) for row in rows if row["sps"])


def ship(run: Run, snapshot: Optional[Path] = None, chosen: Optional[str] = None) -> Path:
    """The final policy of a run that has reached the end of its plan to `run.shipped`, with its Args and
    its campaign record (method, env steps, stages, wall time, hardware), for scripts/evaluate.py; the
    optimizers and random states stay in the run's own checkpoint in campaign/, which resumes it. With
    `snapshot`, that earlier checkpoint of the run instead (its record says at which step of the plan), the record
    saying how it was `chosen`."""
    path = snapshot or checkpoint_of(run)
    ckpt = load_checkpoint(path)
    a, progress = ckpt["args"], ckpt["progress"]
    if progress["global_step"] < run.args.total_timesteps and snapshot is None:
        raise SystemExit(f"{run.name}: at step {progress['global_step']:,} of {run.args.total_timesteps:,}; "
                         f"ship it when it has run to the end ({run.command})")
    wall = training_wall_s(checkpoint_of(run).with_name("progress.csv"), a["num_envs"] * a.get("num_steps", 0),
                           progress["global_step"])
    return ship_checkpoint(path, run.shipped, run.command, {
        "method": run.method or f"{run.what} (PPO, sparse reward, curiosity {a['curiosity']}; experiments/paper.py)",
        "env steps": f"{progress['global_step']:,}" + ("" if progress["global_step"] >= run.args.total_timesteps
                                                       else f" (of the {run.args.total_timesteps:,} planned)"),
        "stages": ", ".join(f"{stage} from step {step:,}" for step, stage in progress["stage_changes"]),
        "wall time": f"{wall / 3600:.1f} h of training iterations (rollouts and updates, summed from progress.csv; "
                     "evaluations, start-ups and pauses not counted), across sessions, with whatever else ran beside it",
        "hardware": hardware(f"physx_cpu with {a['num_envs']} env processes, the networks on the CPU"),
        **({"chosen": chosen} if chosen else {}),
    })


def hardware(how: str = "physx_cpu") -> str:
    """The campaign record's hardware line: this machine, and `how` the run used it."""
    return f"{platform.machine()}, {os.cpu_count()} CPU cores{'' if torch.cuda.is_available() else ', no GPU'}; {how}"


def policy_only(ckpt: dict) -> dict:
    """A checkpoint's policy (weights, Args, progress) without what only resumes its run (optimizers, RNG states, the
    name of a SAC run's replay buffer's file). A SAC run's critics, target critics and entropy coefficient stay
    beside its actor: a new run starts from all of them (sac.py --init-from). Policies shipped before 2026-12-05 kept
    the actor alone."""
    policy = {k: v for k, v in ckpt.items() if k not in ("optimizer", "icm_optimizer", "rng", "replay_buffer")}
    if ckpt.get("sac") is not None:
        policy["sac"] = {k: v for k, v in ckpt["sac"].items() if not k.endswith("optimizer")}
    return policy


def ship_checkpoint(checkpoint: Path, out: Path, command: str, record: dict, progress_csv: Optional[Path] = None,
                    csv_out: Optional[Path] = None) -> Path:
    """The one way a policy ships: `checkpoint`'s policy (its weights, Args and progress; the optimizers and random
    states stay behind with the run, which they resume) to `out` with its campaign record (the `command` that
    made it and the `record`'s lines: method, env steps, wall time, hardware), for scripts/evaluate.py; the run's
    `progress_csv` copied to `csv_out` beside it when given."""
    policy = policy_only(load_checkpoint(checkpoint))
    policy["campaign"] = dict(command=command, record=record)
    out.parent.mkdir(parents=True, exist_ok=True)
    torch.save(policy, out)
    if progress_csv is not None and progress_csv.exists():
        shutil.copyfile(progress_csv, csv_out)
    print(f"shipped {checkpoint} -> {out}")
    return out
