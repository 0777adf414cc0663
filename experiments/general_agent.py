"""Train the general agent with our recipe, end to end and resumable: expert demonstrations ->
behaviour cloning -> the expert's takeovers where the clone fails -> cloning again -> (optionally)
PPO fine-tuning on the general task at cp4 -> the shipped checkpoint.

    python -m experiments.general_agent --ship                      # the shipped agent (docs/RESULTS.md)
    python -m experiments.general_agent --ppo-timesteps 400000      # then PPO fine-tuning as well

The shipped agent is the behaviour clone: PPO fine-tuning of it, as far as it was tried (probe 5 in
docs/experiments/general_agent.md), lowered its success, so `--ppo-timesteps` is 0 by default.

Each stage writes into --run-dir and is skipped when its output is there, so an interrupted
campaign continues when the same command runs again (PPO resumes from its checkpoint):
  1. demos/*.npz     the planning expert in pd_joint_delta_pos with DART noise
                     (ms_construction/planning/demos.py): the general task, plus extra episodes of
                     the two tasks the clone found hardest (window, flooring)
  2. bc0/checkpoint.pt baselines/ppo/bc.py on them: actor on the expert's actions, critic on their returns
  3. demos/*_takeovers<r>.npz  DAgger round r: the latest clone runs episodes of its own; where it
                     fails, the expert takes over from the states it led to (DemoCollector.takeovers)
  4. bc<r>/checkpoint.pt the clone of all data so far, the takeovers weighted --takeover-repeats
                     times; steps 3 and 4 repeat for each round
     val<N>_bc<r>.json every clone evaluated on validation seeds (500000 on); their rows make
                     <run-dir>/progress.csv, the campaign's curve (scripts/plot_training.py)
  5. ppo/checkpoint.pt baselines/ppo/ppo.py --checkpoint <the last clone>: sparse reward
                     (Algorithm 1), cp4, critic warmed up first, frozen observation normalization, a
                     behaviour-cloning term on the demonstrations beside the PPO loss
  6. --ship          the final checkpoint, with the campaign's record (env steps, wall time,
                     hardware), to assets/checkpoints/general_agent.pt
Wall time of every stage accumulates across interruptions (in the demonstration files and in
<run-dir>/campaign.json).
"""

from __future__ import annotations

import csv
import json
import shlex
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import tyro

from baselines.ppo import bc, checkpoints, evaluation, ppo
from baselines.ppo.checkpoints import load_checkpoint
from baselines.ppo.evaluation import slot_weights, training_slot_weights
from experiments.campaign import hardware, ship_checkpoint
from ms_construction.curriculum import FINAL_STAGE
from ms_construction.planning.demos import demo_expert_config, load_demos, policy_steps, record_demos, tried_episodes
from ms_construction.reporting import WallTimes

SHIPPED = Path("assets/checkpoints/general_agent.pt")
VALIDATION_SEED = 500_000
"""first seed of the validation episodes (training seeds lie below, the test seeds from 1000000 on)."""


@dataclass
class Args:
    run_dir: Path = Path("runs/general_agent")
    """where the campaign's stages write."""
    demos: int = 2200
    """expert episodes of the general task (seeds 100000 on; failed ones are dropped)."""
    window_demos: int = 1500
    """extra expert episodes of WindowInstallation-v1 (seeds 200000 on)."""
    flooring_demos: int = 300
    """extra expert episodes of Flooring-v1 (seeds 300000 on)."""
    window_takeovers: tuple[int, ...] = (1000, 1200)
    """WindowInstallation-v1 episodes the clone runs for the expert's takeovers, one number per DAgger
    round (round r: seeds 400000 + 10000 (r - 1) on)."""
    flooring_takeovers: tuple[int, ...] = (400, 600)
    """the same for Flooring-v1 (round r: seeds 450000 + 10000 (r - 1) on)."""
    ceiling_takeovers: tuple[int, ...] = (0, 600)
    """the same for CeilingInstallation-v1 (round r: seeds 480000 + 5000 (r - 1) on)."""
    takeover_repeats: int = 5
    """how many times each takeover step counts in the cloning (bc.py --repeats)."""
    validation_episodes: int = 200
    """episodes per task on which every clone is evaluated (seeds 500000 on, never trained on), for
    <run-dir>/progress.csv: the campaign's curve (scripts/plot_training.py)."""
    workers: int = 2
    """processes recording demonstrations."""
    bc_epochs: int = 100
    """behaviour-cloning epochs."""
    bc_obs_noise: float = 0.0
    """std of the noise on the clone's normalized inputs in training (bc.py --obs-noise)."""
    ppo_timesteps: int = 0
    """env steps of PPO fine-tuning of the clone (0: ship the behaviour clone)."""
    ppo_num_envs: int = 4
    """env processes of PPO (physx_cpu); more than the cores keeps them busy while the learner works."""
    ppo_learning_rate: float = 3e-5
    """small: the clone already places, PPO refines it."""
    ppo_target_kl: float = 0.02
    """stops an update that would move the policy far from the one that collected the data."""
    bc_coef: float = 0.5
    """weight of the behaviour-cloning term during PPO."""
    critic_warmup_iterations: int = 3
    """first PPO iterations that train only the value function."""
    seed: int = 1
    """seed of behaviour cloning and PPO."""
    branch_preference: Literal["nearest", "fixed"] = "nearest"
    """the expert's choice among several ways to reach a configuration (ExpertConfig.branch_preference):
    `nearest` to the arm (the shipped clone's demonstrations, which reach some goal slots two ways: the clone
    fails where they part, docs/experiments/general_agent.md) or `fixed`, the same way for the same goal slot every time."""
    demo_pace: Literal["slow", "fast"] = "slow"
    """the expert's speed in demonstrations and takeovers (ms_construction/planning/demos.py DEMO_PACES): `slow`,
    every joint at 0.55 of its limits (the shipped clones'), or `fast`, as quick as the delta actions allow with
    room to spare (shorter episodes: slack before the step limit for the clone)."""
    direct_paths: bool = False
    """the expert takes a straight (or one-corner) joint path wherever one is free, RRTConnect only elsewhere
    (ExpertConfig.direct_first): the same start and goal give the same motion, where RRTConnect's paths wander
    differently every time and a clone averages them (docs/experiments/general_agent.md, 'the quick one-way expert')."""
    goal_slots: tuple[int, ...] = ()
    """demonstrate, take over, validate and fine-tune on these goal slots of every task type only (indices 0-2;
    default: all): the imitation recipe on the openings a test holds out (experiments/unseen_openings.py)."""
    ship: bool = False
    """copy the result, with the campaign's record, to assets/checkpoints/general_agent.pt."""


DEMO_SETS = (("general", "ConstructionPickPlace-v1", 100_000, "demos"),
             ("window", "WindowInstallation-v1", 200_000, "window_demos"),
             ("flooring", "Flooring-v1", 300_000, "flooring_demos"))
TAKEOVER_SETS = (("window_takeovers", "WindowInstallation-v1", 400_000, 10_000, "window_takeovers"),
                 ("flooring_takeovers", "Flooring-v1", 450_000, 10_000, "flooring_takeovers"),
                 ("ceiling_takeovers", "CeilingInstallation-v1", 480_000, 5_000, "ceiling_takeovers"))


def main(args: Args) -> Path:
    args.run_dir.mkdir(parents=True, exist_ok=True)
    wall_times = WallTimes(args.run_dir / "campaign.json")
    timed, record = wall_times.timed, wall_times.record
    task_kwargs = {"goal_slot_weights": slot_weights(args.goal_slots)} if args.goal_slots else None
    if args.goal_slots and args.ship:
        raise SystemExit("--goal-slots trains on some openings only: its agent is an experiment's, not the shipped one")

    def collect(sets, policy=None, dagger_round: int = 0) -> list[Path]:
        """The demonstrations of `sets` (or, in DAgger round r >= 1, the expert's takeovers of `policy`)."""
        files = []
        for name, env_id, seed, *per_round, count in sets:
            path, wanted = args.run_dir / "demos" / f"{name}.npz", getattr(args, count)
            if dagger_round:
                wanted = wanted[dagger_round - 1] if dagger_round <= len(wanted) else 0
                seed += per_round[0] * (dagger_round - 1)
                path = path.with_name(f"{name}{dagger_round}.npz")
            if wanted <= 0:
                continue
            if tried_episodes(path) < wanted:
                record_demos(path, wanted, env_id=env_id, seed=seed, workers=args.workers, save_every=100, resume=True,
                             policy=policy, load_policy=checkpoints.load_policy,
                             expert=demo_expert_config(args.branch_preference, args.demo_pace, args.direct_paths),
                             env_kwargs=task_kwargs)
            files.append(path)
        return files

    def clone(out: Path, files: list[Path], repeats: tuple[int, ...] = ()) -> None:
        if not out.exists():
            timed("behaviour cloning", lambda: bc.main(bc.Args(demos=tuple(files), out=out, epochs=args.bc_epochs,
                                                               obs_noise=args.bc_obs_noise, seed=args.seed,
                                                               repeats=repeats)))

    curve = []

    def validate(ckpt: Path, r: int, files: list[Path]) -> None:
        """Evaluate clone `r` on the validation seeds (once) and add its row to the campaign's curve."""
        path = args.run_dir / f"val{args.validation_episodes}_bc{r}.json"
        if not path.exists():
            timed("validation", lambda: evaluation.main(evaluation.Args(
                checkpoint=ckpt, all=True, episodes=args.validation_episodes, seed=VALIDATION_SEED,
                goal_slots=args.goal_slots, json=path)))
        tasks = json.loads(path.read_text())["tasks"].values()
        steps = sum(len(e["actions"]) for f in files for e in load_demos(f)[0]) + sum(map(policy_steps, files))
        curve.append(dict(global_step=steps, stage="clone" if r == 0 else f"DAgger round {r}",
                          pick_success=min(t["pick_success"] for t in tasks),
                          place_success=min(t["place_success"] for t in tasks),
                          extrinsic_return=sum(t["mean_return"] for t in tasks) / 3,
                          eval_place_success=sum(t["place_success"] for t in tasks) / 3))

    demo_files = collect(DEMO_SETS)
    bc_ckpt = args.run_dir / "bc0" / "checkpoint.pt"
    clone(bc_ckpt, demo_files)
    validate(bc_ckpt, 0, demo_files)
    takeover_files: list[Path] = []
    rounds = max(len(args.window_takeovers), len(args.flooring_takeovers), len(args.ceiling_takeovers))
    for r in range(1, rounds + 1):  # DAgger: the latest clone's failures, taken over; all data cloned again
        takeover_files += collect(TAKEOVER_SETS, policy=bc_ckpt, dagger_round=r)
        bc_ckpt = args.run_dir / f"bc{r}" / "checkpoint.pt"
        clone(bc_ckpt, demo_files + takeover_files,
              (1,) * len(demo_files) + (args.takeover_repeats,) * len(takeover_files))
        validate(bc_ckpt, r, demo_files + takeover_files)
    with open(args.run_dir / "progress.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(curve[0]))
        writer.writeheader()
        writer.writerows(curve)
    ppo_ckpt = args.run_dir / "ppo" / "checkpoint.pt"
    final = bc_ckpt
    if args.ppo_timesteps > 0:
        if ppo_ckpt.exists():
            timed("PPO", lambda: ppo.main(ppo.Args.of(resume=str(ppo_ckpt))))
        else:
            timed("PPO", lambda: ppo.main(ppo.Args.of(
                checkpoint=str(bc_ckpt), env_id="ConstructionPickPlace-v1", reward_mode="sparse", curriculum=(FINAL_STAGE,),
                curiosity="none", freeze_obs_norm=True, critic_warmup_iterations=args.critic_warmup_iterations,
                demos=tuple(map(str, demo_files + takeover_files)), bc_coef=args.bc_coef, total_timesteps=args.ppo_timesteps,
                num_envs=args.ppo_num_envs, num_steps=250, num_minibatches=4, learning_rate=args.ppo_learning_rate,
                target_kl=args.ppo_target_kl, seed=args.seed, log_dir=str(args.run_dir), exp_name="ppo",
                sim_backend="physx_cpu", goal_slot_weights=training_slot_weights(args.goal_slots))))
        final = ppo_ckpt
    if args.ship:
        ship(args, final, demo_files, takeover_files, record)
    return final


def ship(args: Args, final: Path, demo_files: list[Path], takeover_files: list[Path], record: dict) -> None:
    """Copy `final` to assets/checkpoints/ with the campaign's record; its CSV beside it."""
    demos, takeovers = ([load_demos(p) for p in files] for files in (demo_files, takeover_files))
    kept, tried = sum(len(d) for d, _, _ in demos), sum(t for _, t, _ in demos)
    demo_steps = sum(len(e["actions"]) for d, _, _ in demos for e in d)
    takeover_steps = sum(len(e["actions"]) for d, _, _ in takeovers for e in d)
    clone_steps = sum(map(policy_steps, takeover_files))
    wall = {"demonstrations": sum(w for _, _, w in demos), "takeovers": sum(w for _, _, w in takeovers),
            **record["wall_s"]}
    ppo_steps = load_checkpoint(final)["progress"]["global_step"] if final.parent.name == "ppo" else 0
    total = demo_steps + takeover_steps + clone_steps + ppo_steps
    progress = final.parent / "progress.csv" if final.parent.name == "ppo" else args.run_dir / "progress.csv"
    ship_checkpoint(final, SHIPPED, "python -m experiments.general_agent " + " ".join(shlex.quote(a) for a in sys.argv[1:]), {
        "expert demonstrations": f"{kept} placed episodes kept of {tried} tried; {demo_steps} env steps in the kept ones",
        "expert takeovers": f"{sum(len(d) for d, _, _ in takeovers)} placed takeovers where a clone failed, in "
                            f"{sum(t for _, t, _ in takeovers)} episodes of the clones ({len(takeover_files)} "
                            f"files of DAgger rounds); {clone_steps} env steps of the clones, {takeover_steps} of "
                            f"the expert in the kept takeovers",
        "PPO fine-tuning": f"{ppo_steps} env steps" if ppo_steps else "none (the shipped agent is the clone)",
        "env steps in all": f"{total}, the failed demonstration episodes not counted (budget: 8,000,000)",
        "wall time": ", ".join(f"{k} {v / 60:.0f} min" for k, v in wall.items())
        + f"; {sum(wall.values()) / 3600:.2f} h in all (budget: 6 h)",
        "hardware": hardware(),
    }, progress, SHIPPED.with_name("general_agent_progress.csv"))


if __name__ == "__main__":
    main(tyro.cli(Args))
