"""Many physx_cpu envs behind ManiSkillVectorEnv's interface: worker processes, same-step resets, torch.

ManiSkill simulates many envs in one process only on physx_cuda; on physx_cpu a process holds one
env. `CPUVectorEnv` runs `num_envs` of them, the first in the calling process (the learner's) and
the others in gymnasium AsyncVectorEnv worker processes, and gives them the interface of
ManiSkillVectorEnv, so that a learner written for the GPU (ManiSkill's PPO baseline,
baselines/ppo/ppo.py) runs unchanged on a CPU machine:

- torch tensors in and out, batched over envs, on `device`;
- same-step resets: an env whose episode ends (terminated or truncated) is reset within that step, as
  ManiSkillVectorEnv does (gymnasium 1.0's AsyncVectorEnv would reset it on the *next* step and return
  a transition that belongs to no episode). The step returns the new episode's first observation;
  `info["final_observation"]`, `info["final_info"]` (the ended episode's last info, with "episode":
  return, episode_len, success_once as ManiSkill's `record_metrics` gives them) and the mask
  `info["_final_info"]` describe the envs whose episode ended, and are absent when none did;
- `call(name, *args)` calls a method of each env (the task's own, e.g.
  `set_curriculum_stage`) and returns the results.

Only the ended episodes' info travels from the workers: the per-step info of ManiSkillVectorEnv is
not returned (fewer bytes and less work per step for the learner, which waits for every step).

Why the first env runs in the learner's process: a learner that sends actions and then blocks until
the workers answer leaves its core idle, and on a virtual machine an idle core is halted and woken
again for every step (on this project's 2-core VM a pipe round trip took several times longer
when the waiting side slept than when both sides were busy). Stepping env 0 itself while the workers
step the others keeps the learner's core busy, and once env 0 is done it polls the workers' pipes
instead of sleeping on them (only while the envs fit the cores: a polling learner would otherwise
take a core from a worker). `first_env_in_process=False` puts every env in a worker, as before.
The samples are the same either way: episode starts are drawn from each env's own seeded generators
(ManiSkill's `enhanced_determinism`, on by default here), so an env in the learner's process neither
moves the learner's random numbers nor depends on them, and every run is reproducible from its seed.

On physx_cuda use ManiSkillVectorEnv itself.

    envs = CPUVectorEnv("Flooring-v1", num_envs=2, env_kwargs=dict(obs_mode="state", control_mode="pd_joint_delta_pos"))
    obs, _ = envs.reset(seed=0)
    obs, reward, terminated, truncated, info = envs.step(torch.zeros(2, *envs.single_action_space.shape))
    envs.close()
"""

from __future__ import annotations

import functools
import os
import signal
from typing import Callable, Optional, Sequence, Union

import gymnasium as gym
import numpy as np
import torch

from ms_construction.envs.construction_env import default_render_backend


class SameStepReset(gym.Wrapper):
    """Worker side of `CPUVectorEnv`: resets the env in the step that ends its episode and reports the
    end in `info` (final_observation, final_info, terminated, truncated), so that AsyncVectorEnv always
    sees an episode that goes on and never resets on its own. A step that ends nothing has an empty
    info (nothing to send)."""

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if not (terminated or truncated):
            return obs, reward, False, False, {}
        ended = dict(final_observation=obs, final_info=info, terminated=bool(terminated), truncated=bool(truncated))
        obs, _ = self.env.reset()
        return obs, reward, False, False, ended


def _make_worker_env(env_id: str, env_kwargs: dict, video_dir: Optional[str], index: int,
                     wrappers: Sequence[Callable[[gym.Env], gym.Env]], creator_pid: int) -> gym.Env:
    """The env of worker `index`, made in the worker process (and once, for its spaces, by
    AsyncVectorEnv in the process that creates the vector env, `creator_pid`)."""
    from mani_skill.utils.wrappers import CPUGymWrapper

    if os.getpid() != creator_pid:
        # Ctrl-C and a SIGTERM to the process group reach every worker: the learner decides when to
        # stop and closes the workers; a worker stopped in the middle of a step would only print a traceback
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        # one intra-op thread: the env's tensors are a few numbers, and torch's default (a thread per
        # core in every worker) only adds threads that compete with the learner and the other workers
        torch.set_num_threads(1)
    env = gym.make(env_id, num_envs=1, sim_backend="physx_cpu", **env_kwargs)
    for wrap in wrappers:
        env = wrap(env)
    if video_dir is not None and index == 0:
        from mani_skill.utils.wrappers import RecordEpisode

        env = RecordEpisode(env, video_dir, save_trajectory=False, video_fps=20)
    return SameStepReset(CPUGymWrapper(env, record_metrics=True))


def _to_torch(x, device: torch.device):
    """numpy arrays (nested in dicts) as tensors; gymnasium's per-key masks `_key` dropped (every env in
    `final_info` has the same keys: `_final_info` is their mask)."""
    if isinstance(x, dict):
        return {k: _to_torch(v, device) for k, v in x.items() if not (k.startswith("_") and k[1:] in x)}
    if isinstance(x, np.ndarray) and x.dtype != object:
        return torch.as_tensor(x, device=device)
    return x


def _concat_infos(a: dict, b: dict, na: int, nb: int) -> dict:
    """Two vector infos (gymnasium's layout: per key an array over the envs, or a dict of them, and the
    mask `_key` of the envs that have it) of `na` and `nb` envs as one of `na + nb` envs."""
    out = {}
    keys = a.keys() | b.keys()
    for key in keys - {"_" + k for k in keys}:
        va, vb = a.get(key), b.get(key)
        if isinstance(va if va is not None else vb, dict):
            out[key] = _concat_infos(va or {}, vb or {}, na, nb)
        else:
            like = va if va is not None else vb
            blank = lambda n: (np.full(n, None, dtype=object) if like.dtype == object  # noqa: E731
                               else np.zeros((n, *like.shape[1:]), like.dtype))
            out[key] = np.concatenate([va if va is not None else blank(na), vb if vb is not None else blank(nb)])
        out["_" + key] = np.concatenate([a.get("_" + key, np.zeros(na, bool)), b.get("_" + key, np.zeros(nb, bool))])
    return out


class CPUVectorEnv:
    """`num_envs` physx_cpu envs of `env_id` (each `gym.make(env_id, **env_kwargs)`, the first in this
    process, the others in worker processes) with ManiSkillVectorEnv's interface; see the module docstring.

    Args:
        env_id: a registered ManiSkill env id.
        num_envs: envs, one per process (this one and `num_envs - 1` workers).
        env_kwargs: keyword arguments of gym.make (obs_mode, control_mode, reward_mode, render_mode, ...).
        device: where the returned tensors live (the learner's device).
        video_dir: record the first env's episodes there as videos (RecordEpisode; needs
            render_mode="rgb_array" in env_kwargs).
        wrappers: applied to each env (the batched ManiSkill env of one), innermost first, e.g. a
            gym.Wrapper class; they must pickle (defined at the top level of a module).
        first_env_in_process: run env 0 in this process (see the module docstring); False: every env
            in a worker process.
    """

    def __init__(self, env_id: str, num_envs: int, env_kwargs: Optional[dict] = None,
                 device: Union[str, torch.device] = "cpu", video_dir: Optional[str] = None,
                 wrappers: Sequence[Callable[[gym.Env], gym.Env]] = (), first_env_in_process: bool = True):
        # the render backend is chosen here, once, so that no worker probes for (and warns about) a
        # missing CUDA device
        env_kwargs = dict(render_backend=default_render_backend(), enhanced_determinism=True, **(env_kwargs or {}))
        self.num_envs, self.device = num_envs, torch.device(device)
        make = [functools.partial(_make_worker_env, env_id, env_kwargs, None if video_dir is None else str(video_dir), i,
                                  tuple(wrappers), os.getpid()) for i in range(num_envs)]
        self.in_process = 1 if first_env_in_process else 0
        self.local = gym.vector.SyncVectorEnv(make[:1]) if self.in_process else None
        # forkserver: workers start from a clean process, not a copy of the learner (its torch threads,
        # its CUDA context)
        self.workers = (gym.vector.AsyncVectorEnv(make[self.in_process:], context="forkserver")
                        if num_envs > self.in_process else None)
        self._poll = bool(self.in_process) and num_envs <= (os.cpu_count() or 1)
        spaces = self.local if self.local is not None else self.workers
        self.single_observation_space = spaces.single_observation_space
        self.single_action_space = spaces.single_action_space

    def _joined(self, local: Optional[tuple], workers: Optional[tuple]) -> tuple:
        """The results (arrays..., info) of the env in this process and of the workers as one batch."""
        if local is None or workers is None:
            return workers if local is None else local
        *arrays, (info_local, info_workers) = zip(local, workers)
        return (*[np.concatenate(pair) for pair in arrays],
                _concat_infos(info_local, info_workers, self.in_process, self.num_envs - self.in_process))

    def reset(self, *, seed: Union[int, Sequence[int], None] = None, options: Optional[dict] = None):
        """Reset every env (env i with seed `seed + i`, or `seed[i]` for a list): (obs, info)."""
        n = self.in_process
        if seed is not None:
            seed = [seed + i for i in range(self.num_envs)] if isinstance(seed, int) else list(seed)
        if self.workers is not None:
            self.workers.reset_async(seed=seed and seed[n:], options=options)
        local = self.local.reset(seed=seed and seed[:n], options=options) if n else None
        obs, info = self._joined(local, self.workers.reset_wait() if self.workers is not None else None)
        return torch.as_tensor(obs, device=self.device), _to_torch(info, self.device)

    def _wait_for_workers(self) -> None:
        """Poll the workers' pipes until every one has answered (see the module docstring)."""
        if self._poll:
            pipes = self.workers.parent_pipes
            while not all(p.poll() for p in pipes):
                pass

    def step(self, actions: torch.Tensor):
        """One step of every env: (obs, reward, terminated, truncated, info), same-step resets."""
        actions, n = actions.cpu().numpy(), self.in_process
        if self.workers is not None:
            self.workers.step_async(actions[n:])
        local = self.local.step(actions[:n]) if n else None
        if self.workers is not None:
            self._wait_for_workers()
        obs, reward, _, _, info = self._joined(local, self.workers.step_wait() if self.workers is not None else None)
        obs = torch.as_tensor(obs, device=self.device)
        reward = torch.as_tensor(reward, dtype=torch.float32, device=self.device)
        terminated = torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)
        truncated = torch.zeros_like(terminated)
        if "final_info" not in info:
            return obs, reward, terminated, truncated, {}
        terminated[:] = torch.as_tensor(info["terminated"])
        truncated[:] = torch.as_tensor(info["truncated"])
        ended = torch.as_tensor(info["_final_info"], device=self.device)
        return obs, reward, terminated, truncated, dict(
            final_observation=torch.as_tensor(info["final_observation"], device=self.device),
            final_info=_to_torch(info["final_info"], self.device),
            _final_info=ended, _final_observation=ended)

    def call(self, name: str, *args, **kwargs) -> tuple:
        """`name(*args, **kwargs)` of every env (the first that has it, outermost wrapper first, down
        to the task itself); each env's result."""
        return tuple(r for part in (self.local, self.workers) if part is not None for r in part.call(name, *args, **kwargs))

    @property
    def worker_processes(self) -> list:
        """The worker processes (multiprocessing.Process), one per env but the first."""
        return [] if self.workers is None else self.workers.processes

    def close(self) -> None:
        for part in (self.local, self.workers):
            if part is not None:
                part.close()
