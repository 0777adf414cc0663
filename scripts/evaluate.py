"""Evaluate a trained agent: pick and place success (Wilson 95% intervals), return, length.

    python scripts/evaluate.py --checkpoint assets/checkpoints/general_agent.pt --env-id Flooring-v1 --episodes 100 --json out.json
    python scripts/evaluate.py --all --episodes 100 --json outputs/eval/general.json     # our Table II
    python scripts/evaluate.py --all --steps 50000                 # the paper's protocol: 50k steps per task
    python scripts/evaluate.py --all --episodes 10 --video-dir outputs/videos             # one video per task

Options: `python scripts/evaluate.py --help`; the protocol (seeds, deterministic actions, what the
JSON holds): baselines/ppo/evaluation.py.
"""

import tyro

from baselines.ppo.evaluation import Args, main

if __name__ == "__main__":
    main(tyro.cli(Args))
