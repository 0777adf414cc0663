"""The pipelines that make the shipped agents and the published results (each with one command), apart from the
learner (baselines/ppo/)."""
