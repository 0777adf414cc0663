"""The suction plate's grasp sensor on its own (ms_construction/agents/suction_gripper.py); its
grasp and hold inside the tasks are tested in tests/test_envs.py."""

import math

import numpy as np
import torch

from ms_construction.agents.suction_gripper import MAX_GRASP_INCIDENCE_DEG, grasp_ray, out_of_reach
from ms_construction.parameters import SiteParams

SIZE = torch.tensor([SiteParams().floor_panel.size], dtype=torch.float32)


def ray(tilt_deg: float, height: float = 0.05, x: float = 0.0) -> tuple[float, bool]:
    """tcp in the element frame: `height` above the face, its ray tilted about x, aimed at (x, 0)."""
    a = np.deg2rad(180 + tilt_deg)
    y = -height * np.tan(np.deg2rad(tilt_deg))
    face_z = float(SIZE[0, 2]) / 2
    pose = torch.tensor([[x, y, face_z + height, np.cos(a / 2), np.sin(a / 2), 0, 0]], dtype=torch.float32)
    dist, hit = grasp_ray(pose, SIZE)
    return float(dist[0]), bool(hit[0])


def test_grasp_ray_needs_the_face_in_front_within_the_incidence_limit():
    """The plate's ray (its z axis) must meet the grasp face from outside, within 60 degrees of the
    face normal and inside the face's rectangle."""
    assert MAX_GRASP_INCIDENCE_DEG == 60.0
    half_x = float(SIZE[0, 0]) / 2
    dist, hit = ray(0)
    assert hit and math.isclose(dist, 0.05, abs_tol=1e-5)
    dist, hit = ray(59)
    assert hit and math.isclose(dist, 0.05 / np.cos(np.deg2rad(59)), rel_tol=1e-4)
    assert ray(61) == (math.inf, False), "beyond the 60 degree incidence limit"
    assert ray(0, x=half_x + 0.01) == (math.inf, False), "the ray misses the face"
    assert ray(0, height=-0.02) == (math.inf, False), "the plate behind the face"


def test_grasp_ray_is_batched_per_env():
    poses = torch.tensor([[0, 0, 0.1, 0, 1, 0, 0], [0, 0, 0.3, 0, 1, 0, 0], [0, 0, 0.3, 1, 0, 0, 0]], dtype=torch.float32)
    dist, hit = grasp_ray(poses, SIZE.expand(3, 3))
    face_z = float(SIZE[0, 2]) / 2
    assert hit.tolist() == [True, True, False]  # the third points away from the face
    np.testing.assert_allclose(dist[:2].numpy(), [0.1 - face_z, 0.3 - face_z], atol=1e-6)
    assert math.isinf(float(dist[2]))


def test_the_reach_test_never_skips_a_grasp_the_ray_would_make():
    """physx_cpu skips the ray where `out_of_reach` says no grasp can happen: over random tcp poses around
    the element, every pose whose ray meets the face within tau_pick is in reach, and far poses are not."""
    gen = torch.Generator().manual_seed(0)
    n, half_diagonal = 20_000, float(torch.linalg.norm(SIZE[0])) / 2
    q = torch.randn(n, 4, generator=gen)
    q[: n // 2] = torch.tensor([0.0, 1.0, 0.0, 0.0]) + 0.4 * q[: n // 2]  # half of them facing the face, roughly
    pos = (torch.rand(n, 3, generator=gen) * 2 - 1) * 0.6
    pos[: n // 2, 2] = pos[: n // 2, 2].abs() / 6  # and up to 0.1 m above the element's centre
    poses = torch.cat([pos, q / q.norm(dim=-1, keepdim=True)], -1)
    for tau_pick in (0.02, 0.1, 0.3):
        dist, _ = grasp_ray(poses, SIZE.expand(n, 3))
        grasped = dist <= tau_pick
        reach = torch.tensor([not out_of_reach(p[:3].numpy(), half_diagonal, tau_pick) for p in poses])
        assert grasped.sum() > 100 and bool(reach[grasped].all()), "a grasp the ray makes is never skipped"
        assert not bool(reach.all()), "and the test does skip poses away from the element"
