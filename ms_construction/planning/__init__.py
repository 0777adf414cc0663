"""A sampling-based motion-planning expert for the construction tasks (mplib 0.1.1, RRTConnect).

    from ms_construction.planning import MotionPlanningExpert
    expert = MotionPlanningExpert(gym.make("Flooring-v1", control_mode="pd_joint_pos"))
    result = expert.run(seed=0)  # EpisodeResult: picked, placed, steps, planning_time, failure

Modules: expert (the phases), arm_planner (mplib RRTConnect and collision checks),
collision_model (the arm, a held element and the site for FCL), trajectory (straight tcp lines,
time parameterization).
"""

from ms_construction.planning.expert import EpisodeResult, ExpertConfig, MotionPlanningExpert

__all__ = ["EpisodeResult", "ExpertConfig", "MotionPlanningExpert"]
