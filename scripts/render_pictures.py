"""Pictures for the README: the site, every task at its start and installed, and the site with obstacles.

    python scripts/render_pictures.py          # writes docs/images/*.png

The installed view puts the arm (by IK) and the element at the episode's goal, as a successful
placement looks; nothing is simulated in between.
"""

from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import imageio.v3 as iio
import numpy as np
import sapien
import torch
import tyro
from mani_skill.utils import sapien_utils

from ms_construction.envs import TASK_ENV_IDS
from ms_construction.kinematics import ArmIK


OBSTACLES_SEED = 1_000_010
"""the obstacle picture's episode: its worker walks past while the expert carries the panel."""


@dataclass
class Args:
    out: Path = Path("docs/images")
    seed: int = 2


def _pose(raw: torch.Tensor) -> sapien.Pose:
    t = raw[0].cpu().numpy()
    return sapien.Pose(t[:3], t[3:])


def _render(env) -> np.ndarray:
    return env.render()[0].cpu().numpy()


def install(env) -> None:
    """Arm and element as at a successful placement of the current episode."""
    u = env.unwrapped
    k = int(u.task_id[0])
    goal, grasp = _pose(u.goal_pose.raw_pose), _pose(u._grasp_in_el[k:k + 1])
    q = ArmIK(u.agent.robot).solve(goal * grasp)
    u.agent.robot.set_qpos(torch.tensor(q[None], dtype=torch.float32))
    u.obj.set_pose(goal)


def site_overview(out: Path) -> None:
    """Cut-away view from above: the second-story slab is hidden to show the layout below it."""
    env = gym.make("ConstructionPickPlace-v1", render_mode="rgb_array", obs_mode="none", reward_mode="none")
    env.reset(seed=0)
    outside = _render(env)
    _from_above(env)
    above = _render(env)
    iio.imwrite(out / "site.png", np.concatenate([outside, above], 1))
    env.close()


def _from_above(env) -> None:
    """The human-render camera above the site, the second-story slab hidden."""
    u = env.unwrapped
    for entity in u.site.parts["upper_slab"]._objs:
        entity.find_component_by_type(sapien.render.RenderBodyComponent).visibility = 0.0
    cam = u.scene.human_render_cameras["render_camera"].camera
    cam.set_local_pose(sapien_utils.look_at(eye=[-2.6, -3.2, 4.6], target=[-0.2, -0.1, 0.6]).sp)


def obstacles_episode(out: Path, seed: int = OBSTACLES_SEED) -> None:
    """The planning expert placing a floor panel while a worker walks across the cell (`obstacles="moving"`): four
    moments of the episode, seen from above (the slab hidden): the start, the worker in its lane (twice), the end."""
    from ms_construction.planning import MotionPlanningExpert

    env = gym.make("Flooring-v1", render_mode="rgb_array", obs_mode="state", reward_mode="sparse",
                   control_mode="pd_joint_pos", obstacles="moving")
    frames, walking = [], []
    expert = MotionPlanningExpert(env)
    step = expert._step

    def recorded(target):
        ended = step(target)
        frames.append(_render(env))
        walking.append(bool(env.unwrapped.worker_walking()[0]))
        return ended

    expert._step = recorded
    for _ in range(5):  # RRTConnect's paths vary: the first episode in which the expert gives way to the worker
        frames.clear()
        walking.clear()
        env.reset(seed=seed)
        _from_above(env)
        first = _render(env)
        result = expert.solve(seed)
        if result.placed and result.replans + result.waited_steps + result.escapes > 0:
            break
    lane = [i for i, w in enumerate(walking) if w] or [len(frames) // 2]
    picks = [lane[len(lane) // 4], lane[3 * len(lane) // 4], len(frames) - 1]
    iio.imwrite(out / "obstacles_moving.png", np.concatenate([first] + [frames[i] for i in picks], 1))
    print(f"obstacles_moving.png: seed {seed}, placed {result.placed}, replans {result.replans}, "
          f"escapes {result.escapes}, waited {result.waited_steps} steps, collisions {result.collisions}")
    expert.close()
    env.close()


def main(args: Args) -> None:
    args.out.mkdir(parents=True, exist_ok=True)
    site_overview(args.out)
    obstacles_episode(args.out)
    for env_id in TASK_ENV_IDS.values():
        env = gym.make(env_id, render_mode="rgb_array", obs_mode="none", reward_mode="none")
        env.reset(seed=args.seed)
        start = _render(env)
        install(env)
        iio.imwrite(args.out / f"{env_id}.png", np.concatenate([start, _render(env)], 1))
        env.close()
    print(f"wrote {sorted(p.name for p in args.out.glob('*.png'))} to {args.out}")


if __name__ == "__main__":
    main(tyro.cli(Args))
