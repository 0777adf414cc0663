"""Our batched quaternion helpers agree with ManiSkill's (rotation_conversions, Pose).

The task keeps its own (ms_construction/rotations.py) because they are faster on its hot path:
`python scripts/benchmark_rotations.py` measures both (docs/BENCHMARKS.md).
"""

import pytest
import torch
from mani_skill.utils.geometry import rotation_conversions as rc
from mani_skill.utils.structs import Pose

from ms_construction import rotations as r

N = 257


@pytest.fixture
def data():
    g = torch.Generator().manual_seed(0)
    q = [torch.nn.functional.normalize(torch.randn(N, 4, generator=g), dim=-1) for _ in range(2)]
    p = [torch.cat([torch.randn(N, 3, generator=g), qi], -1) for qi in q]
    return q, p, torch.randn(N, 3, generator=g)


def _same_rotation(a: torch.Tensor, b: torch.Tensor) -> None:
    # q and -q are the same rotation
    torch.testing.assert_close(a * torch.sign((a * b).sum(-1, keepdim=True)), b, atol=1e-5, rtol=1e-5)


def test_products_inverses_and_rotations_agree_with_rotation_conversions(data):
    (q1, q2), _, v = data
    torch.testing.assert_close(r.qmul(q1, q2), rc.quaternion_raw_multiply(q1, q2), atol=1e-6, rtol=1e-5)
    torch.testing.assert_close(r.qconj(q1), rc.quaternion_invert(q1))
    torch.testing.assert_close(r.qrot(q1, v), rc.quaternion_apply(q1, v), atol=1e-5, rtol=1e-5)
    m = rc.quaternion_to_matrix(q1)
    torch.testing.assert_close(r.qmat(q1), m, atol=1e-6, rtol=1e-5)
    for i in range(3):
        torch.testing.assert_close(r.qaxis(q1, i), m[..., i], atol=1e-6, rtol=1e-5)


def test_angles_axis_angles_and_yaw_quaternions_agree_with_rotation_conversions(data):
    (q1, _), _, _ = data
    rotvec = rc.quaternion_to_axis_angle(rc.standardize_quaternion(q1))  # the short way round, as ours
    torch.testing.assert_close(r.quat_to_rotvec(q1), rotvec, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(r.qangle_deg(q1), torch.rad2deg(torch.linalg.norm(rotvec, dim=-1)), atol=1e-3, rtol=1e-5)
    deg = torch.linspace(-360, 360, N)
    axis_angle = torch.stack([torch.zeros(N), torch.zeros(N), torch.deg2rad(deg)], -1)
    _same_rotation(r.quat_z(deg), rc.axis_angle_to_quaternion(axis_angle))


def test_pose_composition_and_inverse_agree_with_maniskill_pose(data):
    _, (p1, p2), _ = data
    a, b = Pose.create(p1), Pose.create(p2)
    ours, theirs = r.pose_mul(p1, p2), (a * b).raw_pose
    torch.testing.assert_close(ours[:, :3], theirs[:, :3], atol=1e-5, rtol=1e-5)
    _same_rotation(ours[:, 3:], theirs[:, 3:])
    ours, theirs = r.pose_inv(p1), a.inv().raw_pose
    torch.testing.assert_close(ours[:, :3], theirs[:, :3], atol=1e-5, rtol=1e-5)
    _same_rotation(ours[:, 3:], theirs[:, 3:])
