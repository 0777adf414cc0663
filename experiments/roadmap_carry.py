"""A carry measure that prescribes no route, probed: a roadmap's cost-to-go among the obstacles, beside the dense
reward's carry and the straight joint-space distance, along the planning expert's placed episodes.

    python -m experiments.roadmap_carry                  # 6 layouts per task where only a detour was clear
    python -m experiments.roadmap_carry --per-task 12

Among obstacles the dense reward pays the carry along one clear way: a start path the obstacles leave clear, else a
via searched round them at reset (obstacle version 7), else a detour. Along the expert's own ways round them it hardly
falls (`python -m experiments.obstacles --carry-along-expert 12`). This probe asks whether a measure that pays any
clear way would. At the episode's start it takes the vertices of the goal slot's start paths from the grasp side
(the episode's, a searched via among them) and draws configurations around them (a point of a path plus Gaussian
noise), keeps those clear of the site and the obstacles (the start paths' own
checkers), joins each to its nearest by straight joint moves, each checked clear only when it would settle a node
(Dijkstra from the installation configurations, lazily), and measures the arm by the least, over the tree's edges,
of a weight times its joint-space offset from the edge plus the tree's length from the edge's point to the
installation. Nothing here trains, and the tasks' reward is unchanged: it measures whether such a measure would fall
along the expert's ways, and what it would cost at a reset.

The expert plans with OMPL's RRT, whose draws are its own: its episodes, so the correlations, differ from run to run.
"""

from __future__ import annotations

import heapq
import json
import time
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
import tyro

from experiments.obstacles import HeldCarries, layouts, rank_correlation
from ms_construction.curriculum import FINAL_STAGE
from ms_construction.envs import PAPER_TASK_ENV_IDS
from ms_construction.envs.carry_geometry import wrap
from ms_construction.goal_configurations import (START_TURNS_DEG, _collides_at, path_clear, path_point,
                                                  symmetry_period)
from ms_construction.parameters import ELEMENT_KINDS


@dataclass
class Args:
    per_task: int = 6
    """layouts per task type (windows, floor panels): the first the expert placed of those where the obstacles left
    only a detour clear (experiments/obstacles.py LAYOUT_GROUPS, `clear-way`)."""
    draws: int = 300
    """configurations drawn per episode (those that collide are dropped)."""
    neighbours: int = 8
    """each node's nearest nodes (joint-space L1) it may be joined to."""
    spacing: float = 0.08
    """rad (joint-space L1) between the checked points of an edge."""
    weights: tuple[float, ...] = (3.0, 10.0)
    """the offset weights tried (the dense reward's carry counts 3 per rad off a start path, 25 off a via's)."""
    out: Path = Path("docs/data/obstacles")
    """where experiments/obstacles.py wrote the expert's static episodes (which seeds it placed)."""


class HeldSteps(HeldCarries):
    """HeldCarries, and the arm's configuration and the element's turn on the plate at each held step."""

    def __init__(self, env):
        super().__init__(env)
        self.qpos: list[np.ndarray] = []
        self.turns: list[float] = []

    def step(self, action):
        result = super().step(action)
        if bool(result[4]["is_grasped"][0]):
            u = self.env.unwrapped
            self.qpos.append(u.agent.robot.get_qpos()[0].numpy().astype(float))
            self.turns.append(float(u.plate_turn()[0]))
        return result


def wrapped(d: np.ndarray, period: float) -> np.ndarray:
    """Joint moves `d` [..., 6] with joint 6's part taken modulo the element's symmetry `period`."""
    d = d.copy()
    d[..., 5] = wrap(torch.from_numpy(d[..., 5]), torch.tensor(period)).numpy()
    return d


@dataclass
class Roadmap:
    nodes: np.ndarray
    """[N, 6] clear configurations, the installation configurations first."""
    to_go: np.ndarray
    """[N] rad: the tree's length from each node to an installation (inf: not reached)."""
    parent: np.ndarray
    """[N] the next node toward the installation (-1: an installation, or not reached)."""
    period: float
    checked: int
    """edges checked."""


def build(u, args: Args, rng: np.random.Generator) -> Roadmap:
    """The roadmap of the module docstring for the episode `u` stands in, after the element was grasped."""
    kind, slot = int(u.task_id[0]), int(u.goal_slot[0])
    period = symmetry_period(ELEMENT_KINDS[kind])
    turns = [float(np.deg2rad(t)) for t in START_TURNS_DEG]
    ways, paths = u.obstacle_ways(), u.geometry.paths
    side = max(int(u.carry_side[0]), 0)
    waypoints = ways.waypoints[0].numpy().astype(float)
    lines = [w for m, w in enumerate(waypoints) if m % 2 == side and bool(paths["kept"][kind, slot, m])]
    planners = u._path_planners(kind, with_site=True)
    limits = u.agent.robot.get_qlimits()[0].numpy().astype(float).T
    roots = np.unique(np.array([w[0] for w in lines]), axis=0)
    # the paths' own vertices (out of the opening along the plate's axis, the via, the lift), then the draws
    drawn = [q for w in lines for q in w[1:]]
    for _ in range(args.draws):
        q = path_point(lines[rng.integers(len(lines))], rng.uniform())
        drawn.append(np.clip(q + rng.normal(0.0, rng.uniform(0.05, 1.0), 6), *limits))
    nodes = [*roots, *(q for q in drawn if not _collides_at(planners, q, turns))]
    x = np.array(nodes)
    dist = np.abs(wrapped(x[:, None] - x[None], period)).sum(-1)
    near = np.argsort(dist, -1)[:, 1:args.neighbours + 1]
    to_go, parent = np.full(len(x), np.inf), np.full(len(x), -1)
    heap, checked = [(0.0, i, -1) for i in range(len(roots))], 0
    while heap:
        cost, i, p = heapq.heappop(heap)
        if np.isfinite(to_go[i]):
            continue
        if p >= 0:
            checked += 1
            b = x[p] + wrapped(x[i] - x[p], period)
            if not path_clear(planners, np.array([x[p], b]), turns, max(1, int(np.ceil(dist[p, i] / args.spacing)))):
                continue
        to_go[i], parent[i] = cost, p
        for j in {*near[i].tolist(), *np.nonzero(near == i)[0].tolist()}:  # the nearest either way
            if not np.isfinite(to_go[j]):
                heapq.heappush(heap, (cost + dist[i, j], j, i))
    return Roadmap(x, to_go, parent, period, checked)


def cost_to_go(q: np.ndarray, turn: float, road: Roadmap, weight: float) -> float:
    """The least, over the roadmap's reached nodes and tree edges, of `weight` times the joint-space (L1) offset of the
    arm at `q` (joint 6 shifted by the element's `turn`) from it plus the tree's length from there to the
    installation."""
    q = q.copy()
    q[5] -= turn
    reached = np.isfinite(road.to_go)
    best = (weight * np.abs(wrapped(q - road.nodes[reached], road.period)).sum(-1) + road.to_go[reached]).min()
    kids = np.nonzero(reached & (road.parent >= 0))[0]
    if len(kids):
        start = road.nodes[road.parent[kids]]
        seg = wrapped(road.nodes[kids] - start, road.period)
        rel = wrapped(q - start, road.period)
        t = np.clip((rel[:, :5] * seg[:, :5]).sum(-1) / np.maximum((seg[:, :5] ** 2).sum(-1), 1e-9), 0.0, 1.0)
        off = np.abs(wrapped(rel - t[:, None] * seg, road.period)).sum(-1)
        best = min(best, (weight * off + road.to_go[road.parent[kids]] + t * np.abs(seg).sum(-1)).min())
    return float(best)


def main(args: Args) -> list[str]:
    from ms_construction.planning import MotionPlanningExpert

    if args.per_task < 1 or args.draws < 1 or args.neighbours < 1 or args.spacing <= 0:
        raise SystemExit("--per-task, --draws, --neighbours and --spacing must be positive")
    measures = ["the dense reward's carry", "straight joint distance",
                *[f"roadmap, weight {w:g}" for w in args.weights]]
    lines = ["| task | expert episodes placed | " + " | ".join(measures) + " | roadmap: built in (s) / nodes / edges "
             "checked, median |", "|---|---|" + "---|" * (len(measures) + 1)]
    for kind in ("window", "flooring"):
        env_id = PAPER_TASK_ENV_IDS[kind]
        solved = [e["seed"] for e in json.loads((args.out / f"expert_static_{kind}.json").read_text())["episodes"]
                  if e["placed"]]
        found = layouts(env_id, solved)
        seeds = [s for s in solved if found[s]["clear-way"] == "a detour only"][:args.per_task]
        env = HeldSteps(gym.make(env_id, num_envs=1, obs_mode="state", control_mode="pd_joint_pos",
                                 reward_mode="dense", sim_backend="physx_cpu", curriculum_stage=FINAL_STAGE,
                                 obstacles="static"))
        expert = MotionPlanningExpert(env)
        rhos, built = {m: [] for m in measures}, []
        for seed in seeds:
            env.carries.clear(), env.qpos.clear(), env.turns.clear()
            if not (expert.run(seed).placed and env.qpos):
                continue
            start = time.perf_counter()
            road = build(env.unwrapped, args, np.random.default_rng(seed))
            built.append((time.perf_counter() - start, len(road.nodes), road.checked))
            install = road.nodes[road.to_go == 0]
            courses = [env.carries, [np.abs(wrapped(np.r_[q[:5], q[5] - t] - install, road.period)).sum(-1).min()
                                     for q, t in zip(env.qpos, env.turns)]]
            courses += [[cost_to_go(q, t, road, w) for q, t in zip(env.qpos, env.turns)] for w in args.weights]
            for m, course in zip(measures, courses):
                rhos[m].append(rank_correlation(course))
        expert.close()
        env.close()
        if built:
            cells = [f"{np.median(r):.2f} ({max(r):.2f})" for r in rhos.values()]
            b = np.median(np.array(built), 0)
            lines.append(f"| {kind} | {len(built)} of {len(seeds)} | " + " | ".join(cells) +
                         f" | {b[0]:.1f} / {b[1]:.0f} / {b[2]:.0f} |")
    print("Carry against the step while the element was held: rank correlation, median (worst); -1 where it falls all "
          "the way.\n")
    print("\n".join(lines))
    return lines


if __name__ == "__main__":
    main(tyro.cli(Args))
