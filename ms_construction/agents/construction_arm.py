"""The construction arm as a ManiSkill agent (uid `construction_arm`).

A 6-DoF industrial arm on a pedestal with a flat suction plate as its tool (the paper's "gripper
panel"). The URDF is generated and committed (`assets/arm/construction_arm.urdf`); joint drives
follow ManiSkill's convention of gravity-compensated links (balance_passive_force), so the PD gains
only have to hold the payload: they are stiff enough that a 15 kg element at full reach sags by
millimetres (tests/test_arm.py), and the force limits are the URDF's effort limits, which follow the
paper's 400 N tool force limit. The plate's grasp sensor and its hold of an element are
`ms_construction.agents.suction_gripper`.
"""

from copy import deepcopy

import numpy as np
import sapien

from mani_skill.agents.base_agent import BaseAgent, Keyframe
from mani_skill.agents.controllers import (
    PDEEPoseControllerConfig,
    PDEEPosControllerConfig,
    PDJointPosControllerConfig,
    deepcopy_dict,
)
from mani_skill.agents.registration import register_agent
from mani_skill.utils import sapien_utils

from ms_construction.assets import ARM_URDF_PATH, load_manifest

ARM_JOINTS = [f"joint{i}" for i in range(1, 7)]
REST_QPOS = np.array([0.0, -0.2, 0.8, 0.0, np.pi / 2 - 0.6, 0.0])
"""Ready pose: plate facing down, 1.2 m above the ground, in front of the pedestal."""


@register_agent()
class ConstructionArm(BaseAgent):
    uid = "construction_arm"
    urdf_path = str(ARM_URDF_PATH)
    disable_self_collisions = False

    keyframes = dict(rest=Keyframe(qpos=REST_QPOS, pose=sapien.Pose()))

    arm_joint_names = ARM_JOINTS
    ee_link_name = "tcp"
    arm_stiffness = [2e5, 2e5, 1e5, 1e4, 1e4, 5e3]
    """Nm/rad: a 22 kg load (element + plate) at full reach sags by ~2 mrad at the shoulder."""
    arm_damping = [7e3, 8e3, 3e3, 200.0, 250.0, 150.0]
    """Nm s/rad: about critical for the loaded arm stretched out."""

    def __init__(self, *args, **kwargs):
        # refuse to start from a missing or stale URDF before ManiSkill tries to download it
        self.arm_force_limit = load_manifest()["arm"]["effort_limits"]
        super().__init__(*args, **kwargs)

    def _after_init(self):
        self.tcp = sapien_utils.get_obj_by_name(self.robot.get_links(), self.ee_link_name)
        self.plate = sapien_utils.get_obj_by_name(self.robot.get_links(), "suction_plate")

    @property
    def tcp_pose(self):
        """Pose of the suction plate's face centre; its z axis points out of the plate."""
        return self.tcp.pose

    @property
    def _controller_configs(self):
        common = dict(
            stiffness=self.arm_stiffness,
            damping=self.arm_damping,
            force_limit=self.arm_force_limit,
        )
        pd_joint_pos = PDJointPosControllerConfig(
            self.arm_joint_names, lower=None, upper=None, normalize_action=False, **common
        )
        pd_joint_delta_pos = PDJointPosControllerConfig(
            self.arm_joint_names, lower=-0.1, upper=0.1, use_delta=True, **common
        )
        pd_joint_target_delta_pos = deepcopy(pd_joint_delta_pos)
        pd_joint_target_delta_pos.use_target = True
        ee = dict(ee_link=self.ee_link_name, urdf_path=self.urdf_path, **common)
        pd_ee_delta_pos = PDEEPosControllerConfig(self.arm_joint_names, pos_lower=-0.05, pos_upper=0.05, **ee)
        pd_ee_delta_pose = PDEEPoseControllerConfig(
            self.arm_joint_names, pos_lower=-0.05, pos_upper=0.05, rot_lower=-0.1, rot_upper=0.1, **ee
        )
        pd_ee_target_delta_pose = deepcopy(pd_ee_delta_pose)
        pd_ee_target_delta_pose.use_target = True
        # every mode is a dict of parts, one part "arm", as ManiSkill's own robots declare them: its
        # trajectory tools (control mode conversion) read `controller.controllers["arm"]` and
        # `to_action_dict`; the action space stays the arm's flat Box
        return deepcopy_dict(
            dict(
                pd_joint_delta_pos=dict(arm=pd_joint_delta_pos),
                pd_joint_pos=dict(arm=pd_joint_pos),
                pd_joint_target_delta_pos=dict(arm=pd_joint_target_delta_pos),
                pd_ee_delta_pos=dict(arm=pd_ee_delta_pos),
                pd_ee_delta_pose=dict(arm=pd_ee_delta_pose),
                pd_ee_target_delta_pose=dict(arm=pd_ee_target_delta_pose),
            )
        )
