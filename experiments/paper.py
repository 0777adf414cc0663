"""The paper's experiment as ppo.py runs it: its settings and its runs, a campaign (experiments/campaign.py).

    python -m experiments.paper --dry-run                    # the plan, and where each run stands
    python -m experiments.paper                              # run 1 and run 3 (or resume them), one after the other
    python -m experiments.paper --runs paper_general_agent --num-envs 16
    python -m experiments.paper --control-groups             # the control groups, 2M steps each (Fig. 4's length)
    python -m experiments.paper --control-groups --total-timesteps 8000000   # continued to the general agent's 8M
    python -m experiments.paper_report --write-results       # its sections of docs/RESULTS.md and docs/experiments/paper.md, Figures 3 and 4

Ctrl-C or SIGTERM stops the run in progress after its iteration, with a checkpoint; the same command resumes it.

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

import os
from dataclasses import dataclass
from typing import Optional

import tyro

from baselines.ppo.args import Args as PPOArgs
from experiments.campaign import CAMPAIGN_DIR, SHIPPED_DIR, Run, choose, describe, run_or_resume
from ms_construction.envs import PAPER_TASK_ENV_IDS
from ms_construction.curriculum import FINAL_STAGE, STAGE_NAMES

STAGE_STEPS = 2_000_000
"""the paper's steps per curriculum stage."""
UPDATE_SAMPLES = 10_000
"""samples per PPO update (ML-Agents' buffer_size, 10240, rounded to divide a stage)."""
CONTROL_GROUPS = {"ceiling": "controlGroup4.1", "window": "controlGroup4.2", "flooring": "controlGroup4.3"}


def paper_args(num_envs: Optional[int] = None, **overrides) -> PPOArgs:
    """ppo.py Args of the paper setting (see the module docstring), for `num_envs` env processes (default:
    one per CPU core); `overrides` replace any field afterwards."""
    num_envs = num_envs or os.cpu_count() or 1
    if UPDATE_SAMPLES % num_envs:
        raise SystemExit(f"--num-envs {num_envs}: the paper setting's {UPDATE_SAMPLES} samples per update must "
                         f"divide evenly among the envs (use 1, 2, 4, 5, 8, 10, 16, 20, 25, 40, 50, ...)")
    args = PPOArgs.of(
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
    return args.replace(**overrides)


def general_runs(num_envs: Optional[int] = None, seed: int = 1) -> list[Run]:
    """Run 1 (the paper's general agent) and run 3 (its cp1 stage without curiosity)."""
    command = "python -m experiments.paper"
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
    command = "python -m experiments.paper --control-groups" + ("" if total_timesteps == STAGE_STEPS else f" --total-timesteps {total_timesteps}")
    # the 2M point keeps its own file when the run goes on to 8M: both are published
    suffix = "" if total_timesteps == STAGE_STEPS else f"_{total_timesteps // 1_000_000}m"
    return [
        Run(f"control_{kind}", paper_args(num_envs, seed=seed, env_id=env_id, exp_name=f"control_{kind}", curriculum=stages,
                                          total_timesteps=total_timesteps),
            f"{CONTROL_GROUPS[kind]}: {env_id}, cp4 from the first step", command, SHIPPED_DIR / f"control_{kind}{suffix}.pt")
        for kind, env_id in PAPER_TASK_ENV_IDS.items()
    ]


@dataclass
class Args:
    runs: tuple[str, ...] = ("paper_general_agent", "paper_cp1_no_curiosity")
    """which runs of the general agent, in this order (without --control-groups)."""
    control_groups: bool = False
    """run the control groups 4.1 / 4.2 / 4.3 instead: one agent each on CeilingInstallation-v1,
    WindowInstallation-v1 and Flooring-v1, at cp4 from the first step."""
    tasks: tuple[str, ...] = tuple(PAPER_TASK_ENV_IDS)
    """which control groups, in this order: ceiling (4.1), window (4.2), flooring (4.3)."""
    total_timesteps: int = STAGE_STEPS
    """per control group, a multiple of 2M: 2M (the general agent's cp4 stage) or 8M (its whole budget). A run is
    a chain of 2M-step cp4 stages, each restarting the schedules as the general agent's stages do, so the first
    2M steps are the same whatever the total."""
    num_envs: Optional[int] = None
    """env processes (default: one per CPU core); it must divide the 10,000 samples of an update. A run resumed
    from a checkpoint keeps its own."""
    seed: int = 1
    dry_run: bool = False
    """print the plan and where each run stands, and exit."""


def main(args: Args) -> None:
    if args.control_groups:
        unknown = [t for t in args.tasks if t not in PAPER_TASK_ENV_IDS]
        if unknown:
            raise SystemExit(f"--tasks {' '.join(unknown)}: use among {', '.join(PAPER_TASK_ENV_IDS)}")
        plan = {r.name: r for r in control_group_runs(args.total_timesteps, args.num_envs, args.seed)}
        runs = [plan[f"control_{t}"] for t in args.tasks]
    else:
        runs = choose(general_runs(args.num_envs, args.seed), args.runs)
    for run in runs:
        print(describe(run))
    if not args.dry_run:
        for run in runs:
            run_or_resume(run)


if __name__ == "__main__":
    main(tyro.cli(Args))
