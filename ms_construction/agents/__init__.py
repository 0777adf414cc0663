from ms_construction.agents.construction_arm import ConstructionArm

__all__ = ["ConstructionArm"]
