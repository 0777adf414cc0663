"""Expert demonstrations in the learner's control mode (pd_joint_delta_pos), with DART noise.

    record_demos(Path("outputs/demos/general.npz"), episodes=1200)   # scripts/collect_demos.py

The planning expert sends absolute joint targets. `JointTargetsAsDeltas` puts it in front of a
pd_joint_delta_pos env: each target becomes the delta action that sets the same PD target from the
arm's measured joints, `a = (target - qpos) / 0.1` (clipped to [-1, 1]), which is exactly what the
learner's policy must output in that state. Recorded: (observation, that clean action).

DART (Laskey et al. 2017): with `noise > 0` the action *executed* is the clean one plus Gaussian
noise, while the clean one is recorded, so the data show how to return to the expert's path from
states a policy's small errors lead to; the expert tracks its planned targets in closed loop, so
it corrects the noise itself. Joint targets then lag slightly, which the expert's settle steps
absorb; a demonstration is kept only if it placed.

Takeovers (DAgger-style, Ross et al. 2011): `DemoCollector.takeovers` runs a policy (a clone of
these demonstrations) on an episode; where it fails, the episode is restored to the policy's own
states around where it went wrong and the expert solves it from there (`MotionPlanningExpert.solve`),
so the data cover the states the policy actually reaches, not only the expert's.
"""

from __future__ import annotations

import dataclasses
import multiprocessing as mp
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

import gymnasium as gym
import numpy as np
import torch
from tqdm import tqdm

from ms_construction.planning.expert import ExpertConfig, MotionPlanningExpert
from ms_construction.rollout import policy_episode
from ms_construction.parameters import ELEMENT_KINDS
from ms_construction.curriculum import FINAL_STAGE

DELTA_CONTROL_MODE = "pd_joint_delta_pos"
DEMO_EXPERT_CONFIG = ExpertConfig(speed=0.55)
"""The expert slowed so that no joint moves more than 0.1 rad (one full delta action) per step."""
FAST_DEMO_EXPERT_CONFIG = ExpertConfig(speed=0.8, max_joint_step=0.08, good_enough=1.2, rrt_attempts=8)
"""The expert as quick as the delta actions allow with room to spare: every joint at most 0.08 rad per step,
which leaves the shoulder joints (whose limits are lower) 0.8 of their limits instead of 0.55, and more
RRTConnect attempts for a quicker carry. With one way per goal slot its episodes are 12-15% shorter (16-48
episodes per task: ceiling mean 190 -> 161-166 steps, window 174 -> 146, flooring 147 -> 127), which leaves a
clone of them slack before the 250-step limit (docs/experiments/general_agent.md, 'the quick one-way expert')."""
DEMO_PACES = {"slow": DEMO_EXPERT_CONFIG, "fast": FAST_DEMO_EXPERT_CONFIG}
"""--demo-pace of scripts/collect_demos.py and experiments/general_agent.py."""


def demo_expert_config(branch_preference: str = "nearest", pace: str = "slow", direct_first: bool = False) -> ExpertConfig:
    """The demonstrating expert's settings: `pace` (DEMO_PACES) with `branch_preference` and `direct_first`
    (ExpertConfig)."""
    if pace not in DEMO_PACES:
        raise ValueError(f"demonstration pace {pace!r}: use one of {', '.join(DEMO_PACES)}")
    return dataclasses.replace(DEMO_PACES[pace], branch_preference=branch_preference, direct_first=direct_first)


class JointTargetsAsDeltas(gym.Wrapper):
    """Takes absolute joint targets [1, 6], steps a pd_joint_delta_pos env, records (obs, action)."""

    accepts_joint_targets = True

    def __init__(self, env: gym.Env, noise: float = 0.0, seed: int = 0):
        super().__init__(env)
        u = env.unwrapped
        if u.control_mode != DELTA_CONTROL_MODE or u.num_envs != 1:
            raise ValueError(f"JointTargetsAsDeltas wraps one physx_cpu env in {DELTA_CONTROL_MODE}, "
                             f"got {u.control_mode} with {u.num_envs} envs")
        ctrl = u.agent.controller.controllers["arm"] if hasattr(u.agent.controller, "controllers") else u.agent.controller
        self.delta_scale = float(np.asarray(ctrl.config.upper).reshape(-1)[0])
        self.noise = noise
        self.rng = np.random.default_rng(seed)
        self.obs: list[np.ndarray] = []
        self.actions: list[np.ndarray] = []
        self.rewards: list[float] = []
        self._last_obs = None

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        self.obs, self.actions, self.rewards = [], [], []
        self._last_obs = obs
        return obs, info

    def restore(self, state: dict) -> None:
        """Set the episode (just reset) to `state` (from `get_state_dict`), observed from there on."""
        u = self.env.unwrapped
        u.set_state_dict(state)
        self._last_obs = u.get_obs()

    def step(self, target):
        qpos = self.env.unwrapped.agent.robot.get_qpos()
        clean = ((torch.as_tensor(target, dtype=qpos.dtype) - qpos) / self.delta_scale).clamp(-1, 1)
        self.obs.append(self._last_obs[0].cpu().numpy().astype(np.float32))
        self.actions.append(clean[0].cpu().numpy().astype(np.float32))
        executed = clean
        if self.noise > 0:
            executed = (clean + torch.as_tensor(self.rng.normal(0, self.noise, clean.shape), dtype=clean.dtype)).clamp(-1, 1)
        obs, reward, terminated, truncated, info = self.env.step(executed)
        self._last_obs = obs
        self.rewards.append(float(reward.reshape(-1)[0]))
        return obs, reward, terminated, truncated, info


@dataclass
class Demo:
    obs: np.ndarray
    """[T, obs_dim] observations the actions were taken in."""
    actions: np.ndarray
    """[T, 6] clean delta actions in [-1, 1]."""
    rewards: np.ndarray
    """[T] the env's sparse reward (Algorithm 1) of each step."""
    placed: bool
    task: str
    seed: int
    noise: float


class DemoCollector:
    """One env and one expert; `collect(seed, noise)` solves a seeded episode and returns its demo. `env_kwargs`: more
    of the task's kwargs (say, `goal_slot_weights` that draw some goal slots only)."""

    def __init__(self, env_id: str, curriculum_stage: str = FINAL_STAGE, config: ExpertConfig = DEMO_EXPERT_CONFIG,
                 env_kwargs: Optional[dict] = None):
        env = gym.make(env_id, num_envs=1, obs_mode="state", control_mode=DELTA_CONTROL_MODE, reward_mode="sparse",
                       sim_backend="physx_cpu", curriculum_stage=curriculum_stage, **(env_kwargs or {}))
        self.env = JointTargetsAsDeltas(env)
        self.obs_dim = env.observation_space.shape[-1]
        self.expert = MotionPlanningExpert(self.env, config)

    def collect(self, seed: int, noise: float, start_state: Optional[dict] = None) -> Demo:
        """The expert's episode `seed`, from its reset or, given `start_state`, from that state of it."""
        self.env.noise, self.env.rng = noise, np.random.default_rng(seed + 7919)
        self.env.reset(seed=seed)
        if start_state is not None:
            self.env.restore(start_state)
        result = self.expert.solve(seed)
        return Demo(obs=np.stack(self.env.obs) if self.env.obs else np.zeros((0, self.obs_dim), np.float32),
                    actions=np.stack(self.env.actions) if self.env.actions else np.zeros((0, 6), np.float32),
                    rewards=np.array(self.env.rewards, np.float32), placed=result.placed and bool(self.env.actions),
                    task=result.task, seed=seed, noise=noise)

    def takeovers(self, seed: int, noise: float, policy, offsets: tuple[int, ...] = (-30, -10, 15)
                  ) -> tuple[list[Demo], int]:
        """DAgger-style data where `policy` fails: its deterministic episode `seed`; if it does not
        place, the expert takes over from the policy's states `offsets` steps from the one where the
        element came closest to its goal (before: where the policy went wrong; after: where it was
        stuck). Where the element was never nearer its goal than at the start (a floor panel is
        carried away from its recess first), that is the start, and the takeovers are the expert's
        episode from the policy's first steps. Returns the expert's placed takeovers and the env
        steps the policy took."""
        episode = policy_episode(policy, self.env.env, seed, keep_states=True)
        states = episode.states
        if episode.placed:
            return [], len(states)
        closest = int(np.argmin(episode.place_dist))
        demos = []
        for t in sorted({min(max(0, closest + k), len(states) - 1) for k in offsets}):
            demo = self.collect(seed, noise, start_state=states[t])
            if demo.placed:
                demos.append(demo)
        return demos, len(states)

    def close(self) -> None:
        self.expert.close()
        self.env.close()


PolicyLoader = Callable[[Path, str], tuple]
"""(checkpoint path, env id) -> (policy with get_action(obs, deterministic), the env kwargs it acts in)."""
_collector, _policy = None, None


def _collect(job: tuple[str, str, int, float, Optional[str], Optional[PolicyLoader], ExpertConfig, Optional[dict]]
             ) -> tuple[list[dict], int]:
    """One episode in a worker process (its collector kept for the next): the expert's, or with a
    policy checkpoint, the expert's takeovers where that policy fails. Returns the placed
    demonstrations and the env steps the policy took."""
    global _collector, _policy
    env_id, stage, seed, noise, policy_path, load_policy, expert, env_kwargs = job
    torch.set_num_threads(1)
    if _collector is None:
        _collector = DemoCollector(env_id, stage, expert, env_kwargs)
    if policy_path is None:
        demos, policy_steps = [_collector.collect(seed, noise)], 0
    else:
        if _policy is None:
            _policy, env_kwargs = load_policy(Path(policy_path), env_id)
            if env_kwargs.get("obs_elapsed_time"):
                raise ValueError(f"{policy_path}: takeovers record the expert's observations, which have no elapsed-time "
                                 "entry; give a policy trained without --obs-elapsed-time (a behaviour clone)")
        demos, policy_steps = _collector.takeovers(seed, noise, _policy)
    return [dict(obs=d.obs, actions=d.actions, rewards=d.rewards, placed=d.placed, task=d.task, seed=d.seed,
                 noise=d.noise) for d in demos if d.placed], policy_steps


def save_demos(path: Path, demos: list[dict], tried: int, wall_s: float = 0.0, policy_steps: int = 0) -> None:
    """Write atomically (a temporary file, then a rename); `wall_s`: the recording's wall time so far;
    `policy_steps`: env steps a policy took to find the takeover states (not in the demos)."""
    lens = [len(d["actions"]) for d in demos]
    cat = lambda key, empty: np.concatenate([d[key] for d in demos]) if demos else empty  # noqa: E731
    data = dict(
        obs=cat("obs", np.zeros((0, 0), np.float32)), actions=cat("actions", np.zeros((0, 0), np.float32)),
        rewards=cat("rewards", np.zeros(0, np.float32)),
        episode=np.repeat(np.arange(len(demos)), lens),
        task=np.repeat([ELEMENT_KINDS.index(d["task"]) for d in demos], lens),
        seed=np.repeat([d["seed"] for d in demos], lens), noise=np.repeat([d["noise"] for d in demos], lens),
        tried=np.array(tried), wall_s=np.array(wall_s), policy_steps=np.array(policy_steps),
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez_compressed(tmp, **data)
    os.replace(tmp, path)


def load_demos(path: Path) -> tuple[list[dict], int, float]:
    """The episodes of a demonstrations file, how many episodes were tried for it, and the wall time
    its recording took."""
    with np.load(path) as f:
        data = {k: f[k] for k in f.files}  # an npz decompresses an array at every access: once here
    starts = np.flatnonzero(np.diff(data["episode"], prepend=-1))
    demos = []
    for s, e in zip(starts, np.append(starts[1:], len(data["episode"]))):
        demos.append(dict(obs=data["obs"][s:e], actions=data["actions"][s:e], rewards=data["rewards"][s:e], placed=True,
                          task=ELEMENT_KINDS[int(data["task"][s])], seed=int(data["seed"][s]), noise=float(data["noise"][s])))
    return demos, int(data["tried"]), float(data.get("wall_s", 0.0))


def tried_episodes(path: Path) -> int:
    """How many episodes the demonstrations file `path` has tried (0 if it does not exist)."""
    if not Path(path).exists():
        return 0
    with np.load(path) as f:
        return int(f["tried"])


def policy_steps(path: Path) -> int:
    """Env steps the policy took to find the takeover states of the file `path` (0 for the expert's own)."""
    with np.load(path) as f:
        return int(f["policy_steps"]) if "policy_steps" in f.files else 0


def record_demos(out: Path, episodes: int, env_id: str = "ConstructionPickPlace-v1", seed: int = 100_000,
                 noise: float = 0.1, curriculum_stage: str = FINAL_STAGE, workers: int = 2, save_every: int = 50,
                 resume: bool = False, policy: Optional[Path] = None, load_policy: Optional[PolicyLoader] = None,
                 expert: ExpertConfig = DEMO_EXPERT_CONFIG, env_kwargs: Optional[dict] = None) -> Path:
    """Episodes seed, seed + 1, ... (every other one with DART noise `noise`); the placed ones are
    written to `out` every `save_every` episodes and at the end; `resume` continues `out`.
    With a `policy` checkpoint: the expert's takeovers where that policy fails (`DemoCollector.takeovers`);
    `load_policy(path, env_id) -> (policy, control_mode)` loads it in each worker process (a
    module-level function, such as `baselines.ppo.checkpoints.load_policy`: the package does not
    know the learner's network). `expert`: the demonstrating expert's settings (`demo_expert_config`). `env_kwargs`:
    more of the task's kwargs for the episodes (`DemoCollector`)."""
    if policy is not None and load_policy is None:
        raise ValueError("record_demos(policy=...) needs load_policy, e.g. baselines.ppo.checkpoints.load_policy")
    demos, tried, wall_s = load_demos(out) if resume and out.exists() else ([], 0, 0.0)
    steps_of_policy = policy_steps(out) if resume and out.exists() else 0
    start = time.time() - wall_s
    policy_job = (None, None) if policy is None else (str(policy), load_policy)
    jobs = [(env_id, curriculum_stage, seed + i, noise if i % 2 else 0.0, *policy_job, expert, env_kwargs)
            for i in range(tried, episodes)]
    desc = "expert demos" if policy is None else "expert takeovers"
    bar = tqdm(total=episodes, initial=tried, desc=desc, unit="ep", dynamic_ncols=True)
    with mp.get_context("spawn").Pool(workers) as pool:
        for kept, steps in pool.imap(_collect, jobs):
            tried += 1
            demos.extend(kept)
            steps_of_policy += steps
            bar.update()
            bar.set_postfix(kept=len(demos), steps=sum(len(x["actions"]) for x in demos))
            if tried % save_every == 0:
                save_demos(out, demos, tried, time.time() - start, steps_of_policy)
    bar.close()
    save_demos(out, demos, tried, time.time() - start, steps_of_policy)
    print(f"{len(demos)} placed {'takeovers' if policy else 'episodes'} of {tried} episodes, "
          f"{sum(len(x['actions']) for x in demos)} steps -> {out}")
    return out
