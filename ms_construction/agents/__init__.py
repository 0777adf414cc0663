from ms_construction.agents.construction_arm import ConstructionArm
from ms_construction.agents.suction_gripper import SuctionGripper

__all__ = ["ConstructionArm", "SuctionGripper"]
