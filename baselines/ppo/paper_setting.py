"""The paper's experiment as ppo.py runs it: its settings, its runs, and how a campaign of them resumes.

The paper (Unity ML-Agents) fixes the reward (Algorithm 1: our `sparse`), the curiosity bonus, the
curriculum (Table I, each stage 2M steps inheriting every parameter) and the evaluation. It is silent
on the rest; there we follow ML-Agents' documented PPO defaults where they carry over, ppo.py's
otherwise:

| setting | value | source |
|---|---|---|
| reward | sparse (Algorithm 1) | the paper |
| curriculum | cp1 -> cp4, promoted after exactly 2M env steps each, no success gate | the paper |
| curiosity | ICM as ML-Agents computes it, strength 0.02, gamma 0.99, own value head, ignores episode ends | the paper; strength: ML-Agents' example configuration |
| curiosity network | encoder 2 x 128, forward and inverse models 256, lr 3e-4, loss 10 x (0.2 fwd + 0.8 inv) | ML-Agents' defaults |
| policy and value | 2 hidden layers of 128, no observation normalization, raw quaternions | ML-Agents: hidden_units 128, num_layers 2, normalize false |
| samples per update | 10,000 (buffer), minibatches of 1,000, 3 epochs | ML-Agents: buffer_size 10240, batch_size 1024, num_epoch 3; rounded so that a stage is exactly 200 updates |
| learning rate | 3e-4, linear to 0 over each stage | ML-Agents: learning_rate 3e-4, linear schedule over a run's max_steps (each stage a run that inherits the last) |
| clip (epsilon) | 0.2, linear to 0.1 over each stage | ML-Agents: epsilon 0.2, its schedule follows the learning rate's, floor 0.1 |
| entropy (beta) | 5e-3, linear to 1e-5 over each stage | ML-Agents: beta 5e-3, floor 1e-5 |
| GAE | lambda 0.95, gamma 0.99 | ML-Agents: lambd 0.95, extrinsic gamma 0.99 |
| advantages | normalized over the whole update batch | ML-Agents |
| value loss | clipped, weight 0.5; no gradient-norm clipping; no KL early stop | ML-Agents |
| time-limit cut | bootstrapped with the value of the last observation | ML-Agents (an interrupted episode is not done) |
| control mode | pd_joint_delta_pos | ppo.py (the paper's Unity arm is not ours) |
| action noise | Gaussian, log std starts at -0.5, actions clipped to [-1, 1] | ppo.py (ML-Agents: std 1, actions clipped to [-3, 3] / 3) |
| activation | tanh | ppo.py (ML-Agents: Swish) |
| trajectory cuts | a rollout's GAE runs over the whole rollout | ppo.py (ML-Agents cuts trajectories every time_horizon = 64 steps) |
| envs | one per CPU core on physx_cpu | ppo.py (the paper does not say) |

Runs (`RUNS`): `general` is the paper's general agent (8M steps); `no_curiosity` is its cp1 stage again
without curiosity, same seed (what curiosity does here); the control groups 4.1/4.2/4.3 train one
agent per task at cp4 from the first step, in 2M-step stages of cp4 (the general agent's cp4
stage is 2M steps; 4 stages match its whole 8M), each stage restarting the schedules as the
general agent's stages do.
"""

from __future__ import annotations

import csv
import dataclasses
import os
import platform
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import torch

from baselines.ppo import ppo
from baselines.ppo.checkpoints import load_checkpoint
from ms_construction.envs import TASK_ENV_IDS
from ms_construction.curriculum import FINAL_STAGE, STAGE_NAMES

STAGE_STEPS = 2_000_000
"""the paper's steps per curriculum stage."""
UPDATE_SAMPLES = 10_000
"""samples per PPO update (ML-Agents' buffer_size, 10240, rounded to divide a stage)."""
CAMPAIGN_DIR = Path("campaign")
"""where the campaign's runs live; their latest checkpoint and progress CSV are committed."""
CONTROL_GROUPS = {"ceiling": "controlGroup4.1", "window": "controlGroup4.2", "flooring": "controlGroup4.3"}
SHIPPED_DIR = Path("assets/checkpoints")
"""where a finished run's final policy is shipped (`ship`)."""


def paper_args(num_envs: Optional[int] = None, **overrides) -> ppo.Args:
    """ppo.Args of the paper setting (see the module docstring), for `num_envs` env processes (default:
    one per CPU core); `overrides` replace any field afterwards."""
    num_envs = num_envs or os.cpu_count() or 1
    if UPDATE_SAMPLES % num_envs:
        raise SystemExit(f"--num-envs {num_envs}: the paper setting's {UPDATE_SAMPLES} samples per update must "
                         f"divide evenly among the envs (use 1, 2, 4, 5, 8, 10, 16, 20, 25, 40, 50, ...)")
    args = ppo.Args(
        env_id="ConstructionPickPlace-v1", reward_mode="sparse", control_mode="pd_joint_delta_pos",
        sim_backend="physx_cpu", cuda=False,
        curriculum=STAGE_NAMES, stage_timesteps=STAGE_STEPS, total_timesteps=4 * STAGE_STEPS,
        promote_success=2.0,  # never: promotion by step count only
        curiosity="icm", icm_strength=0.02, icm_gamma=0.99, icm_feature_dim=128, icm_hidden_size=256,
        icm_learning_rate=3e-4, icm_forward_weight=0.2,
        hidden_size=128, num_layers=2, norm_obs=False, rotation_features=False,
        num_envs=num_envs, num_steps=UPDATE_SAMPLES // num_envs, num_minibatches=UPDATE_SAMPLES // 1000, update_epochs=3,
        learning_rate=3e-4, stage_schedules=True, clip_coef=0.2, ent_coef=5e-3, gamma=0.99, gae_lambda=0.95,
        norm_adv="batch", clip_vloss=True, vf_coef=0.5, max_grad_norm=None, target_kl=None,
        bootstrap_at_done="truncated", eval_freq=10, checkpoint_freq=5, log_dir=str(CAMPAIGN_DIR),
    )
    return dataclasses.replace(args, **overrides)


@dataclass
class Run:
    """One run of the campaign: its name, its ppo.Args, what it is, the command that runs it, and where
    its final policy is shipped when it has run to the end of its plan (None: not shipped)."""

    name: str
    args: ppo.Args
    what: str
    command: str
    shipped: Optional[Path] = None
    method: Optional[str] = None
    """the campaign record's method line (default: the paper setting's)."""


def general_runs(num_envs: Optional[int] = None, seed: int = 1) -> list[Run]:
    """Run 1 (the paper's general agent) and run 3 (its cp1 stage without curiosity)."""
    command = "python scripts/train_paper_agent.py"
    return [
        Run("paper_general_agent", paper_args(num_envs, seed=seed, exp_name="paper_general_agent"),
            "the paper setting: general task, cp1 -> cp4, 2M steps each", command, SHIPPED_DIR / "paper_general_agent.pt"),
        Run("paper_cp1_no_curiosity", paper_args(num_envs, seed=seed, exp_name="paper_cp1_no_curiosity", curiosity="none",
                                                 curriculum=("cp1",), total_timesteps=STAGE_STEPS),
            "run 1's cp1 stage without curiosity, same seed", command),
    ]


def control_group_runs(total_timesteps: int = STAGE_STEPS, num_envs: Optional[int] = None, seed: int = 1) -> list[Run]:
    """Runs 2: one agent per task at cp4 from the first step, in 2M-step stages of cp4."""
    if total_timesteps % STAGE_STEPS:
        raise SystemExit(f"--total-timesteps {total_timesteps}: use a multiple of {STAGE_STEPS} (one cp4 stage each)")
    stages = (FINAL_STAGE,) * (total_timesteps // STAGE_STEPS)
    command = "python scripts/train_control_groups.py" + ("" if total_timesteps == STAGE_STEPS else f" --total-timesteps {total_timesteps}")
    # the 2M point keeps its own file when the run goes on to 8M: both are published
    suffix = "" if total_timesteps == STAGE_STEPS else f"_{total_timesteps // 1_000_000}m"
    return [
        Run(f"control_{kind}", paper_args(num_envs, seed=seed, env_id=env_id, exp_name=f"control_{kind}", curriculum=stages,
                                          total_timesteps=total_timesteps),
            f"{CONTROL_GROUPS[kind]}: {env_id}, cp4 from the first step", command, SHIPPED_DIR / f"control_{kind}{suffix}.pt")
        for kind, env_id in TASK_ENV_IDS.items()
    ]


def checkpoint_of(run: Run) -> Path:
    return Path(run.args.log_dir) / run.args.exp_name / "checkpoint.pt"


def describe(run: Run) -> str:
    """One line: the run, its budget and stages, and where it stands."""
    a, ckpt = run.args, checkpoint_of(run)
    done = load_checkpoint(ckpt)["progress"]["global_step"] if ckpt.is_file() else 0
    return (f"{run.name}: {run.what}; {a.env_id}, stages {' '.join(a.curriculum)} ({a.stage_timesteps:,} steps each), "
            f"{a.total_timesteps:,} steps, curiosity {a.curiosity}, seed {a.seed}, {a.num_envs} envs x {a.num_steps} steps "
            f"per update; {'resumes at step ' + format(done, ',') if done else 'starts fresh'} ({ckpt})"
            + (f"; ships to {run.shipped}" if run.shipped else ""))


def run_or_resume(run: Run) -> None:
    """Train `run` to the end of its budget, resuming its checkpoint if it has one, and ship its final
    policy (`ship`). A run that was planned with a larger budget than its checkpoint's (control groups
    from 2M to 8M) continues to it."""
    ckpt = checkpoint_of(run)
    ppo.main(dataclasses.replace(run.args, resume=str(ckpt), extend=True) if ckpt.is_file() else run.args)
    if run.shipped is not None:
        ship(run)


def training_wall_s(progress_csv: Path, samples_per_iteration: int) -> float:
    """The wall time of a run's training iterations (rollouts and updates), summed from its progress.csv:
    evaluations, start-ups and the time between sessions are not in it."""
    with open(progress_csv, newline="") as f:
        return sum(samples_per_iteration / float(row["sps"]) for row in csv.DictReader(f) if row["sps"])


def ship(run: Run, before_the_end: bool = False) -> Path:
    """The final policy of a run that has reached the end of its plan to `run.shipped`, with its Args and
    its campaign record (method, env steps, stages, wall time, hardware), for scripts/evaluate.py; the
    optimizers and random states stay in the run's own checkpoint in campaign/, which resumes it. With
    `before_the_end`, the policy where the run stands now (its record says at which step of its plan)."""
    ckpt = load_checkpoint(checkpoint_of(run))
    a, progress = ckpt["args"], ckpt["progress"]
    if progress["global_step"] < run.args.total_timesteps and not before_the_end:
        raise SystemExit(f"{run.name}: at step {progress['global_step']:,} of {run.args.total_timesteps:,}; "
                         f"ship it when it has run to the end ({run.command})")
    wall = training_wall_s(checkpoint_of(run).with_name("progress.csv"), a["num_envs"] * a["num_steps"])
    policy = {k: v for k, v in ckpt.items() if k not in ("optimizer", "icm_optimizer", "rng")}
    policy["campaign"] = dict(command=run.command, record={
        "method": run.method or f"{run.what} (PPO, sparse reward, curiosity {a['curiosity']}; baselines/ppo/paper_setting.py)",
        "env steps": f"{progress['global_step']:,}" + ("" if progress["global_step"] >= run.args.total_timesteps
                                                       else f" (of the {run.args.total_timesteps:,} planned)"),
        "stages": ", ".join(f"{stage} from step {step:,}" for step, stage in progress["stage_changes"]),
        "wall time": f"{wall / 3600:.1f} h of training iterations (rollouts and updates, summed from progress.csv; "
                     "evaluations, start-ups and pauses not counted), across sessions, with whatever else ran beside it",
        "hardware": f"{platform.machine()}, {os.cpu_count()} CPU cores; physx_cpu with {a['num_envs']} env processes, "
                    "the networks on the CPU",
    })
    run.shipped.parent.mkdir(parents=True, exist_ok=True)
    torch.save(policy, run.shipped)
    print(f"shipped {checkpoint_of(run)} -> {run.shipped}")
    return run.shipped
