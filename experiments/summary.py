"""RESULTS' first screen: the headline numbers of every section, each read from the JSON its own command wrote.

    python -m experiments.summary        # rewrites the section `summary` at the top of docs/RESULTS.md

Nothing here runs an agent: a number that a section's command has not produced yet shows as "-". Each row names the
file it comes from; the sections below say how each was made.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

from baselines.ppo import evaluation
from baselines.ppo.evaluation import EXPERT_RESULTS, PAPER_TABLE_II, RESULTS_PATH
from experiments import from_scratch, obstacles, paneling, transfer, unseen_openings
from experiments.obstacles import scene_rows as obstacles_scene_rows
from ms_construction.reporting import update_section

TASKS = tuple(PAPER_TABLE_II)
"""the paper's three tasks, Table II's rows."""
AGENTS = (  # label, how it learnt (None: from the shipped policy's record), its evaluation with the paper's protocol
    ("imitation general agent (general_agent.pt, shipped)",
     "expert demonstrations, behaviour cloning, residual PPO", Path("docs/data/general_agent_eval_50k.json")),
    ("reward-only general agent (scratch_general_agent.pt, shipped)", None, from_scratch.EVAL_JSON),
    ("the paper's setting (paper_general_agent.pt)",
     "PPO + ICM on the sparse reward, Table I's stages, 8M env steps", Path("docs/data/paper/paper_general_agent_eval_50k.json")),
)
GENERALIZATION = (  # label, the agent's label in the obstacle and paneling tables
    ("planning expert", "planning expert"),
    ("imitation general agent", "general agent (imitation: clone + residual PPO)"),
    ("reward-only general agent", "scratch general agent (reward alone, shipped)"),
    ("reward-only general agent of PPO's recipe", "scratch general agent, PPO's (reward alone, before SAC's)"),
    ("the paper's setting", "paper setting (sparse reward, ICM, Table I stages)"),
)
OBSTACLES = Path("docs/data/obstacles/summary.json")
PANELING = Path("docs/data/paneling/summary.json")


def _read(path: Path) -> Optional[dict]:
    return json.loads(path.read_text()) if path.is_file() else None


def _placed(tasks: Optional[dict]) -> list[str]:
    """Placed % per paper task of an evaluation's `tasks` (or "-" where there is none)."""
    return [f"{100 * tasks[t]['place_success']:.1f}" if tasks and t in tasks else "-" for t in TASKS]


def paper_tasks_table() -> list[str]:
    lines = ["| agent | how it learnt | " + " | ".join(f"{t}: placed %" for t in TASKS) + " | source |",
             "|---|---|" + "---|" * len(TASKS) + "---|",
             "| the paper's general agent (Table II, cp4) | PPO + ICM (ML-Agents), Table I's stages, 8M env steps | "
             + " | ".join(f"{PAPER_TABLE_II[t][1]:.2f}" for t in TASKS) + " | the paper |"]
    expert = _read(EXPERT_RESULTS)
    lines.append("| planning expert (100 episodes per task) | - | " + " | ".join(_placed(expert and expert["summary"]))
                 + f" | {EXPERT_RESULTS} |")
    for label, how, path in AGENTS:
        data = _read(path)
        how = how or from_scratch.shipped_how()
        lines.append(f"| {label} | {how} | " + " | ".join(_placed(data and data["tasks"])) + f" | {path} |")
    shipped_from = ((_read(from_scratch.EVAL_JSON) or {}).get("evaluated_as") or {}).get("json")
    how = {"ppo": "PPO on the tasks' default dense reward, one recipe unchanged from step 0",
           "sac": "SAC on the tasks' default dense reward, one recipe unchanged from step 0"}
    for learner in from_scratch.LEARNERS:
        for seed in from_scratch.SEEDS:
            name = f"the recipe from nothing ({learner.upper()}), seed {seed}"
            shown = from_scratch.shown_evaluation(seed, learner)
            if shown is None:
                lines.append(f"| {name} | (its run has not ended: `{from_scratch.seed_run(seed, learner=learner).command}` "
                             "runs it, and its snapshot rule's choice is evaluated at its end) | "
                             + " | ".join("-" for _ in TASKS) + " | |")
                continue
            step, path, chosen = shown
            if shipped_from and path.resolve() == Path(shipped_from).resolve():
                continue  # the shipped reward-only agent's row above is this seed's choice, weight for weight
            which = "the snapshot rule's choice" if chosen else "its latest evaluated snapshot, not yet chosen"
            lines.append(f"| {name}, at {step:,} env steps ({which}) | {how[learner]} | "
                         + " | ".join(_placed(json.loads(path.read_text())["tasks"])) + f" | {path} |")
    return lines


def generalization_table() -> list[str]:
    obstacles, paneling = _read(OBSTACLES), _read(PANELING)
    lines = ["| agent | paneling, a fourth task: placed % | static obstacles: placed % (ceiling / window / flooring) | "
             "a worker walking across too | source |", "|---|---|---|---|---|"]
    for label, key in GENERALIZATION:
        panel = (paneling or {}).get("rows", {}).get(key if key == "planning expert" else f"{key}, zero-shot")
        cells = [f"{100 * panel['place_success']:.1f}" if panel else "-"]
        for scene in ("static", "moving"):
            row = obstacles_scene_rows(obstacles or {}, scene).get(key)
            cells.append(" / ".join(_placed(row)) if row else "-")
        lines.append(f"| {label} | " + " | ".join(cells) + f" | {PANELING}, {OBSTACLES} |")
    return lines


def trained_table() -> list[str]:
    """A row per generalization run that has been evaluated: trained on paneling (its placed %), with an opening of
    each task type held out (placed on the openings it never saw), or among moving obstacles (placed there; the
    snapshots of obstacles.SHOWN of today's version, OBSTACLE_REWARD; the earlier ones are the experiment page's)."""
    lines = ["| trained on | learner, from | seed | env steps | placed %: paneling, or ceiling / window / flooring "
             "| source |", "|---|---|---|---|---|---|"]
    for learner, start, seed in paneling.TRAIN_PLAN:
        path = paneling.train_eval_json(paneling.training_run(start, seed, learner=learner))
        if (data := _read(path)) is not None:
            task = evaluation.task_results(data)[paneling.ENV_ID]
            steps = f"{data['checkpoint_step']:,}" if "checkpoint_step" in data else "-"
            lines.append(f"| paneling | {transfer.start_name(start, learner)} | {seed} | {steps} | "
                         f"{100 * task['place_success']:.1f} | {path} |")
    held_out = (f"openings {' and '.join(map(str, unseen_openings.TRAINED))} (placed at "
                f"{' and '.join(map(str, unseen_openings.HELD_OUT))}, never trained on)")
    if (data := _read(path := unseen_openings.expert_json(seen=False))) is not None:
        lines.append(f"| {held_out} | planning expert (plans each episode, trains on none) | - | - | "
                     + " / ".join(_placed(data["tasks"])) + f" | {path} |")
    for seed in unseen_openings.EVALUATED:
        path = unseen_openings.evaluation_json(seed, seen=False)
        if (data := _read(path)) is not None:
            learner, number = unseen_openings.learner_and_seed(seed)
            lines.append(f"| {held_out} | {learner} | {number or '-'} | {unseen_openings.trained_steps(seed, data)} | "
                         + " / ".join(_placed(data["tasks"])) + f" | {path} |")
    moving = obstacles_scene_rows(_read(OBSTACLES) or {}, "moving")
    built = obstacles_scene_rows(_read(OBSTACLES) or {}, "none")
    earlier = obstacles.earlier_versions()
    for start, learner, share, reward, seed, step in obstacles.SHOWN:
        label = obstacles.trained_label(start, learner, share, reward, seed, step)
        if label not in earlier and (row := moving.get(label)) is not None:
            # what training among obstacles left of the site as built, beside it
            kept = f" (the site as built: {' / '.join(_placed(built[label]))})" if label in built else ""
            lines.append(f"| {obstacles.scene_name(share)}, {obstacles.version_name(reward)} | "
                         f"{transfer.start_name(start, learner)} | {seed} | {step:,} | " + " / ".join(_placed(row))
                         + f"{kept} | {OBSTACLES} |")
    return lines


def summary() -> str:
    return "\n".join([
        "## At a glance", "",
        "The paper's three tasks with its protocol (test seeds from 1,000,000, 50,000 env steps per task, cp4 tolerances, "
        "the policy's mean action):", "", *paper_tasks_table(), "",
        "Generalization, zero-shot: agents trained on the paper's three tasks on the site as built, met with what they "
        "never saw (the expert plans for each episode as it comes; cp4; seeds from 1,000,000):", "",
        *generalization_table(), "",
        "Generalization, trained: the recipe's learners trained on the new setting (or, for openings, on the others); "
        "the same protocols (paneling: 50,000 env steps; openings: 50,000 env steps per task; obstacles: the expert's "
        "solvable seeds, the moving scene). From SAC's agent: the networks of the run the shipped reward-only agent "
        f"comes from ({transfer.SAC_STARTS['shipped']}); from PPO's: {transfer.STARTS['shipped']}. Obstacle rewards "
        f"and start-state devices: experiments/obstacles.py OBSTACLE_REWARDS (today's: "
        f"{obstacles.version_name(obstacles.OBSTACLE_REWARD)}; every earlier version's snapshots: "
        f"[their table](experiments/{obstacles.VERSIONS_PATH.name}#every-version-trained-among-obstacles)).", "",
        *trained_table(), "",
        "*Made by `python -m experiments.summary` from the files named; each section below gives the command that "
        "wrote them, its intervals and its failures.*"])


def main() -> str:
    body = summary()
    update_section(RESULTS_PATH, "summary", body, "Results")
    print(body)
    return body


if __name__ == "__main__":
    main()
