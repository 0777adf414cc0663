"""Behaviour-cloning warm start for PPO: the planning expert's demonstrations -> a ppo.py checkpoint.

    python scripts/collect_demos.py --episodes 1200 --out outputs/demos/general.npz
    python baselines/ppo/bc.py --demos outputs/demos/general.npz --out runs/bc/checkpoint.pt
    python baselines/ppo/ppo.py --checkpoint runs/bc/checkpoint.pt --freeze-obs-norm ...   # fine-tune

The actor's mean is regressed onto the expert's clean delta actions (MSE); the observation
normalization is the demonstrations' mean and variance; the critic is regressed onto the
demonstrations' discounted sparse returns (Algorithm 1's reward), so that PPO's first advantages
come from a value that already knows where placements happen instead of from noise. The result
is an ordinary ppo.py checkpoint (Agent weights, obs normalization, args): `ppo.py --checkpoint`
fine-tunes it, `scripts/evaluate.py` evaluates it.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import tyro
from tqdm import tqdm

from baselines.ppo.checkpoints import Progress, save_checkpoint
from baselines.ppo.checkpoints import make_agent
from baselines.ppo.args import Args as PPOArgs


@dataclass
class Args:
    demos: tuple[Path, ...] = (Path("outputs/demos/general.npz"),)
    """demonstration files from scripts/collect_demos.py (one or more)."""
    out: Path = Path("runs/bc/checkpoint.pt")
    """the checkpoint to write (ppo.py format)."""
    env_id: str = "ConstructionPickPlace-v1"
    """the env the checkpoint is for (the demonstrations' observation layout)."""
    seed: int = 1
    """seed of initialization and minibatch order."""
    epochs: int = 100
    """passes over the demonstrations."""
    batch_size: int = 1024
    """samples per gradient step."""
    learning_rate: float = 1e-3
    """Adam learning rate, cosine-annealed to 0."""
    hidden_size: int = 256
    """width of the networks (as ppo.py's --hidden-size)."""
    rotation_features: bool = True
    """quaternions as rotation-matrix columns (as ppo.py's --rotation-features)."""
    val_fraction: float = 0.05
    """fraction of episodes held out to report the validation loss."""
    gamma: float = 0.99
    """discount of the critic's return targets (as ppo.py's --gamma)."""
    init_logstd: float = -2.3
    """the policy's log std in the checkpoint (std 0.1, the DART noise of the demonstrations): small, so
    that PPO's sampled episodes stay close to the clone's."""
    obs_noise: float = 0.0
    """std of Gaussian noise added to the normalized observation features in training (a regularizer
    for the states a clone's own small errors lead to)."""
    max_episodes: int = 0
    """use only the first this many episodes, in file order (0: all)."""
    repeats: tuple[int, ...] = ()
    """how many times each --demos file's steps count per epoch, in order (missing: 1): weighs the
    few, short takeover demonstrations (collect_demos.py --policy) against the many full episodes."""


def discounted_returns(rewards: np.ndarray, episode: np.ndarray, gamma: float) -> np.ndarray:
    out = np.zeros_like(rewards)
    running = 0.0
    for t in range(len(rewards) - 1, -1, -1):
        if t == len(rewards) - 1 or episode[t + 1] != episode[t]:
            running = 0.0  # every demonstration ends in a placement: terminal
        running = rewards[t] + gamma * running
        out[t] = running
    return out


def main(args: Args) -> Path:
    torch.manual_seed(args.seed)
    if len(args.repeats) > len(args.demos) or any(r < 1 for r in args.repeats):
        raise SystemExit(f"--repeats: at most one whole number >= 1 per --demos file ({len(args.demos)}), got {args.repeats}")
    repeats = list(args.repeats) + [1] * (len(args.demos) - len(args.repeats))
    loaded = [(np.load(path), r) for path, r in zip(args.demos, repeats)]
    files = [f for f, _ in loaded if len(f["episode"])]
    offsets = np.cumsum([0] + [int(f["episode"].max()) + 1 for f in files[:-1]])
    episode = np.concatenate([f["episode"] + o for f, o in zip(files, offsets)])
    weight = np.concatenate([np.full(len(f["episode"]), r) for f, r in loaded if len(f["episode"])])
    keep = episode < args.max_episodes if args.max_episodes else np.ones_like(episode, bool)
    obs, act = (np.concatenate([f[k] for f in files])[keep] for k in ("obs", "actions"))
    ep, weight = episode[keep], weight[keep]
    ret = discounted_returns(np.concatenate([f["rewards"] for f in files])[keep], ep, args.gamma)
    episodes = np.unique(ep)
    rng = np.random.default_rng(args.seed)
    # at least one episode left to train on; a single demonstration is its own validation (in-sample, as printed)
    val_eps = rng.choice(episodes, min(max(1, int(len(episodes) * args.val_fraction)), len(episodes) - 1), replace=False)
    val = np.isin(ep, val_eps) if len(val_eps) else np.ones(len(ep), bool)
    train = ~val if len(val_eps) else val
    obs_t, act_t, ret_t = (torch.as_tensor(x, dtype=torch.float32) for x in (obs, act, ret))
    print(f"{len(episodes)} demonstrations, {len(obs)} steps ({int(train.sum())} train, {int(val.sum())} validation)")

    ppo_args = PPOArgs.of(env_id=args.env_id, control_mode="pd_joint_delta_pos", hidden_size=args.hidden_size,
                       rotation_features=args.rotation_features, seed=args.seed, exp_name=args.out.parent.name)
    agent = make_agent(ppo_args, obs.shape[1], act.shape[1])
    agent.obs_rms.update(agent.features(obs_t[torch.as_tensor(train)]))
    with torch.no_grad():
        agent.actor_logstd.fill_(args.init_logstd)
    params = list(agent.actor_mean.parameters()) + list(agent.critic.parameters())
    optimizer = torch.optim.Adam(params, lr=args.learning_rate)
    train_idx = np.repeat(np.flatnonzero(train), weight[train])
    steps_per_epoch = int(np.ceil(len(train_idx) / args.batch_size))
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, args.epochs * steps_per_epoch)

    def losses(idx, noise=0.0):  # the critic's head 0 is the extrinsic return (a second one is curiosity's)
        x = agent.normalize(obs_t[idx])
        x = x + noise * torch.randn_like(x) if noise else x
        return ((agent.actor_mean(x) - act_t[idx]) ** 2).mean(), ((agent.critic(x)[:, 0] - ret_t[idx]) ** 2).mean()

    t0 = time.time()
    bar = tqdm(range(args.epochs), desc="behaviour cloning", unit="epoch", dynamic_ncols=True)
    for _ in bar:
        rng.shuffle(train_idx)
        for start in range(0, len(train_idx), args.batch_size):
            idx = torch.as_tensor(train_idx[start:start + args.batch_size])
            a_loss, v_loss = losses(idx, args.obs_noise)
            optimizer.zero_grad()
            (a_loss + 0.5 * v_loss).backward()
            optimizer.step()
            sched.step()
        with torch.no_grad():
            va, vv = losses(torch.as_tensor(np.flatnonzero(val)))
        bar.set_postfix(train_action_mse=f"{a_loss.item():.4f}", val_action_mse=f"{va.item():.4f}", val_value_mse=f"{vv.item():.4f}")
    print(f"validation action MSE {va.item():.5f}, value MSE {vv.item():.5f}, {time.time() - t0:.0f} s")

    record = {k: [str(p) for p in v] if k == "demos" else str(v) if isinstance(v, Path) else v
              for k, v in dataclasses.asdict(args).items()}
    record.update(demonstrations=len(episodes), steps=len(obs), val_action_mse=va.item())
    # no optimizer: PPO starts its own from a clone (--checkpoint loads the weights only)
    save_checkpoint(args.out, ppo_args, Progress(), agent, None, None, None, obs.shape[1], act.shape[1], bc=record)
    print(f"wrote {args.out}")
    return args.out


if __name__ == "__main__":
    main(tyro.cli(Args))
