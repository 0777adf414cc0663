"""The main job: an offscreen video of every task with the arm acting at random.

    python scripts/main.py                        # all four tasks, 80 steps each
    python scripts/main.py --env-ids Flooring-v1 --steps 250 --out outputs/videos

(Once a trained agent ships in assets/checkpoints/, this job will show it instead.)
"""

from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import torch
import tyro
from mani_skill.utils.wrappers import RecordEpisode
from tqdm import tqdm

from ms_construction.envs import ENV_IDS


@dataclass
class Args:
    env_ids: tuple[str, ...] = ENV_IDS
    """tasks to record."""
    steps: int = 80
    """steps per video (an episode lasts at most 250)."""
    seed: int = 0
    out: Path = Path("outputs/videos")
    """folder for the mp4 files."""


def main(args: Args) -> None:
    bad = [e for e in args.env_ids if e not in ENV_IDS]
    if bad:
        raise SystemExit(f"unknown env id(s) {bad}; allowed: {', '.join(ENV_IDS)}")
    written = []
    for env_id in tqdm(args.env_ids, desc="recording", unit="task"):
        env = gym.make(env_id, obs_mode="none", render_mode="rgb_array", reward_mode="sparse")
        env = RecordEpisode(env, output_dir=str(args.out), save_trajectory=False, save_on_reset=False, video_fps=20)
        env.reset(seed=args.seed)
        env.action_space.seed(args.seed)
        for _ in range(args.steps):
            env.step(torch.as_tensor(env.action_space.sample()))
        name = f"{env_id}_random_seed{args.seed}"
        env.flush_video(name=name)
        env.close()
        written.append(args.out / f"{name}.mp4")
    print("videos written:")
    for path in written:
        print(f"  {path.resolve()}")


if __name__ == "__main__":
    main(tyro.cli(Args))
