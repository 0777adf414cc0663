"""SAC's runs of the recipe from nothing: its Args on one of the recipe's seeds, and a run (or its resumption) in
parts. SAC met the recipe's target (every task placed >= 90%, picked >= 95% with the paper's protocol) in about a
fifth of PPO's training wall time on this CPU on both seeds (experiments/learners.py), so it is the recipe's learner
(experiments/from_scratch.py `--learner sac`, the default); experiments/learners.py compares the two, and
experiments/transfer.py and unseen_openings.py run it on new settings.

What SAC shares with PPO's recipe: the envs, the tasks' default dense reward, the observation, the near-goal starts
(baselines/sac/sac.py's docstring). Its replay buffer (about 140 MB) is written beside its checkpoint and is not
committed: a run resumes exactly on the machine it ran on; on a fresh machine it goes on with an empty buffer that
its actor refills first (`refill_lost_buffer`, recorded in its checkpoint's clock as `refilled_at`)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Callable, Optional

from baselines.sac import sac
from experiments.campaign import CAMPAIGN_DIR, args_checkpoint, checkpoint_step

BUDGET = 2_000_000
"""env steps of a SAC run from nothing per seed: PPO's and SAC's comparison at equal env steps (issue 52: at least
2M)."""
METHOD = ("SAC from nothing on the tasks' default dense reward and near-goal starts (baselines/sac/sac.py's defaults, "
          "experiments/sac_recipe.py); demonstrations: none")
"""the campaign record's method line of a SAC run of the recipe."""


def sac_args(seed: int = 1, **overrides) -> sac.Args:
    """SAC's defaults (chosen for this CPU: baselines/sac/sac.py) on one of the recipe's seeds, in campaign/sac_s<seed>/
    to BUDGET; `overrides` replace any field."""
    return sac.Args(**{**dict(exp_name=f"sac_s{seed}", seed=seed, total_timesteps=BUDGET, log_dir=str(CAMPAIGN_DIR)),
                       **overrides})


def run_sac(a: sac.Args, every: Optional[int] = None, stop: Optional[Callable[[], bool]] = None,
            after_part: Optional[Callable[[int, Path], None]] = None) -> None:
    """Run (or resume) the SAC run `a` to its total_timesteps, from its checkpoint where there is one (a lost replay
    buffer refilled: `refill_lost_buffer`, recorded in the checkpoint). With `every`, in parts ending at multiples of
    it (checkpoint marks, so a part's end is a resume point), each part's end given to `after_part(env steps,
    checkpoint)`; with `stop`, ending after the first part at whose end `stop()` is true (a run resumed inside a part
    finishes the part first, whatever `stop()` says: it ends on a mark, as an uninterrupted run does). SIGTERM or
    Ctrl-C stops it with a checkpoint (sac.py raises SystemExit: no `after_part` for a part cut short)."""
    ckpt = args_checkpoint(a)
    while (done := checkpoint_step(ckpt) if ckpt.is_file() else 0) < a.total_timesteps:
        if done and stop is not None and every is not None and done % every == 0 and stop():
            return
        end = a.total_timesteps if every is None else min((done // every + 1) * every, a.total_timesteps)
        part = dataclasses.replace(a, total_timesteps=end)
        sac.main(dataclasses.replace(part, resume=str(ckpt), extend=True, refill_lost_buffer=True)
                 if ckpt.is_file() else part)
        if after_part is not None:
            after_part(end, ckpt)
        if every is None:
            return
