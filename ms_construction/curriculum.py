"""The paper's tolerance curriculum (Table I) and validation of tolerance overrides."""

from __future__ import annotations

import math
from typing import Mapping, Optional

STAGES: dict[str, dict[str, float]] = {
    # stage: tau_pick (m), tau_place (m), tau_angle (deg), Table I exactly
    "cp1": {"pick": 0.40, "place": 0.50, "angle_deg": 80.0},
    "cp2": {"pick": 0.30, "place": 0.25, "angle_deg": 60.0},
    "cp3": {"pick": 0.30, "place": 0.13, "angle_deg": 40.0},
    "cp4": {"pick": 0.30, "place": 0.10, "angle_deg": 20.0},
}
STAGE_NAMES = tuple(STAGES)
FINAL_STAGE = STAGE_NAMES[-1]
"""the stage every agent is judged at (cp4: the paper's Table II), and the tasks' default."""
TOLERANCE_KEYS = ("pick", "place", "angle_deg")


def stage_tolerances(stage: str) -> dict[str, float]:
    if stage not in STAGES:
        raise ValueError(f"unknown curriculum stage {stage!r}; allowed: {', '.join(STAGE_NAMES)}")
    return dict(STAGES[stage])


def validate_tolerances(overrides: Optional[Mapping[str, float]]) -> dict[str, float]:
    """Check a (partial) tolerance override: known keys, finite positive numbers, angle <= 180."""
    if overrides is None:
        return {}
    if not isinstance(overrides, Mapping):
        raise ValueError(f"tolerances must be a dict with keys {TOLERANCE_KEYS}, got {overrides!r}")
    out = {}
    for key, value in overrides.items():
        if key not in TOLERANCE_KEYS:
            raise ValueError(f"unknown tolerance {key!r}; allowed keys: {', '.join(TOLERANCE_KEYS)}")
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"tolerance {key}={value!r} is not a number") from None
        if not math.isfinite(v) or v <= 0:
            raise ValueError(f"tolerance {key}={value!r} must be a finite number > 0")
        if key == "angle_deg" and v > 180:
            raise ValueError(f"tolerance angle_deg={value!r} must be at most 180 degrees")
        out[key] = v
    return out


def resolve_tolerances(stage: str, overrides: Optional[Mapping[str, float]] = None) -> dict[str, float]:
    """The stage's tolerances with any overrides applied."""
    tol = stage_tolerances(stage)
    tol.update(validate_tolerances(overrides))
    return tol
