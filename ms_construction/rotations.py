"""Batched quaternion arithmetic ([w, x, y, z], shape [..., 4]) in few torch ops.

ManiSkill's rotation_conversions spells the Hamilton product out term by term (about twenty small
tensor ops per call) and its Pose composes through them; on physx_cpu with one env, op count is step
time, so the task code uses these equivalents: a product is one gather and one multiply-sum, a
rotation two cross products. `scripts/benchmark_rotations.py` times each against ManiSkill's
(docs/BENCHMARKS.md) and tests/test_rotations.py checks that they agree.
"""

from __future__ import annotations

import functools

import torch

# q1 * q2 = sum_b L[a, b] q2[b] with L[a, b] = SIGN[a, b] * q1[IDX[a, b]]
_IDX = [[0, 1, 2, 3], [1, 0, 3, 2], [2, 3, 0, 1], [3, 2, 1, 0]]
_SIGN = [[1, -1, -1, -1], [1, 1, -1, 1], [1, 1, 1, -1], [1, -1, 1, 1]]


@functools.lru_cache(maxsize=None)
def _constants(device: torch.device, dtype: torch.dtype):
    idx = torch.tensor(_IDX, device=device)
    sign = torch.tensor(_SIGN, device=device, dtype=dtype)
    eye = torch.eye(3, device=device, dtype=dtype)
    conj = torch.tensor([1.0, -1.0, -1.0, -1.0], device=device, dtype=dtype)
    return idx, sign, eye, conj


def qmul(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Hamilton product a * b."""
    idx, sign, _, _ = _constants(a.device, a.dtype)
    return ((a[..., idx] * sign) * b[..., None, :]).sum(-1)


def qconj(q: torch.Tensor) -> torch.Tensor:
    """Conjugate (the inverse of a unit quaternion)."""
    return q * _constants(q.device, q.dtype)[3]


def qrot(q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Rotate vectors v [..., 3] by unit quaternions q: v + 2w(u x v) + 2u x (u x v)."""
    u = q[..., 1:]
    t = 2 * torch.linalg.cross(u, v)
    return v + q[..., :1] * t + torch.linalg.cross(u, t)


def qaxis(q: torch.Tensor, i: int) -> torch.Tensor:
    """The i-th column (0 x, 1 y, 2 z) of the rotation matrices of unit quaternions."""
    return qrot(q, _constants(q.device, q.dtype)[2][i].expand(*q.shape[:-1], 3))


def qmat(q: torch.Tensor) -> torch.Tensor:
    """Rotation matrices [..., 3, 3] of unit quaternions."""
    eye = _constants(q.device, q.dtype)[2]
    return qrot(q[..., None, :], eye.expand(*q.shape[:-1], 3, 3)).transpose(-1, -2)


def qangle_deg(q: torch.Tensor) -> torch.Tensor:
    """Rotation angle of unit quaternions, degrees in [0, 180]."""
    return torch.rad2deg(2 * torch.acos(q[..., 0].abs().clamp(max=1.0)))


def quat_z(deg: torch.Tensor) -> torch.Tensor:
    """Rotations about z by `deg` degrees."""
    half = torch.deg2rad(deg) / 2
    zero = torch.zeros_like(half)
    return torch.stack([torch.cos(half), zero, zero, torch.sin(half)], -1)


def pose_mul(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Compose raw poses [..., 7] (p, q): a * b."""
    return torch.cat([a[..., :3] + qrot(a[..., 3:], b[..., :3]), qmul(a[..., 3:], b[..., 3:])], -1)


def pose_inv(a: torch.Tensor) -> torch.Tensor:
    qi = qconj(a[..., 3:])
    return torch.cat([-qrot(qi, a[..., :3]), qi], -1)


def quat_to_rotvec(q: torch.Tensor) -> torch.Tensor:
    """Axis-angle vectors of unit quaternions, taking the short way round."""
    q = torch.where(q[..., :1] < 0, -q, q)
    s = torch.linalg.norm(q[..., 1:], dim=-1, keepdim=True)
    angle = 2 * torch.atan2(s, q[..., :1])
    return q[..., 1:] * torch.where(s > 1e-8, angle / s.clamp(min=1e-8), torch.full_like(s, 2.0))
