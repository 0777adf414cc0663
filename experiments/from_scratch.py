"""The general agent learnt from reward alone: no demonstrations, no expert states, no cloned weights.

    python -m experiments.from_scratch --dry-run        # the plan, and where each run stands
    python -m experiments.from_scratch                  # run (or resume) it; ships when it reaches its budget
    python -m experiments.from_scratch --ship-now       # ship the policy where the run stands now

One PPO run (baselines/ppo/ppo.py) on ConstructionPickPlace-v1, resumed from its checkpoint in campaign/ when it
has one (commit the checkpoint and progress.csv between sessions), shipped to
assets/checkpoints/scratch_general_agent.pt with its campaign record. The recipe, and what each part is for:

| setting | value | why |
|---|---|---|
| reward | normalized_dense: the tasks' dense reward / 5 | its carry term is linear in the arm's joint-space distance from the installation configuration (IK of the goal, ms_construction/goal_configurations.py), so it pulls from the pick, the way the turret's limits allow |
| success | absorbing: bootstrapped with its reward for ever | the critic never trains on a state after success; its guess let hovering near the goal outvalue placing |
| start states | half the training episodes start held on a collision-free joint path out of the goal (`set_near_goal_starts`), the radius widening from 0.1 of the path by 0.1 whenever 60% of them place | reverse curriculum generation (Florensa et al. 2017) from resets the env computes by IK: no demonstrations; evaluation always resets as usual |
| discount | gamma 0.95, GAE lambda 0.95 | values of a few dozen steps: the dense reward carries the rest, and the critic learns them quickly |
| updates | 2,000 samples (2 envs x 1,000 steps), 8 epochs of 8 minibatches, KL stop 0.1 | more gradient steps per env step: env steps are the cost on a CPU |
| curiosity | none | the dense reward explores |
| curriculum | cp4 from the first step | the target is judged at cp4 |
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from typing import Optional

import tyro

from baselines.ppo import ppo
from baselines.ppo.paper_setting import CAMPAIGN_DIR, SHIPPED_DIR, Run, describe, run_or_resume, ship

BUDGET = 20_000_000
"""env steps at most (the issue's budget on this CPU)."""
COMMAND = "python -m experiments.from_scratch"


def scratch_args(num_envs: Optional[int] = None, **overrides) -> ppo.Args:
    """ppo.Args of the from-scratch recipe (see the module docstring); `overrides` replace any field afterwards."""
    num_envs = num_envs or os.cpu_count() or 1
    args = ppo.Args(
        env_id="ConstructionPickPlace-v1", reward_mode="normalized_dense", control_mode="pd_joint_delta_pos",
        sim_backend="physx_cpu", cuda=False, curriculum=("cp4",), total_timesteps=BUDGET, curiosity="none",
        success_value="absorbing", bootstrap_at_done="always", gamma=0.95, gae_lambda=0.95,
        num_envs=num_envs, num_steps=2000 // num_envs, update_epochs=8, num_minibatches=8, target_kl=0.1,
        near_goal_share=0.5, near_goal_radius=0.1, near_goal_step=0.1, near_goal_promote=0.6,
        eval_freq=25, checkpoint_freq=10, log_dir=str(CAMPAIGN_DIR),
    )
    return dataclasses.replace(args, **overrides)


def scratch_runs(num_envs: Optional[int] = None, seed: int = 1) -> list[Run]:
    return [Run("scratch_general_agent", scratch_args(num_envs, seed=seed, exp_name="scratch_general_agent"),
                "the general agent from reward alone: no demonstrations", COMMAND,
                SHIPPED_DIR / "scratch_general_agent.pt",
                method="PPO from scratch on the dense reward with near-goal start states (experiments/from_scratch.py); "
                       "demonstrations: none")]


@dataclass
class Args:
    num_envs: Optional[int] = None
    """env processes (default: one per CPU core); a run resumed from a checkpoint keeps its own."""
    seed: int = 1
    dry_run: bool = False
    """print the plan and where the run stands, and exit."""
    ship_now: bool = False
    """ship the policy where the run stands now (its record says at which step of the plan), and exit."""


def main(args: Args) -> None:
    for run in scratch_runs(args.num_envs, args.seed):
        print(describe(run))
        if args.ship_now:
            ship(run, before_the_end=True)
        elif not args.dry_run:
            run_or_resume(run)


if __name__ == "__main__":
    main(tyro.cli(Args))
