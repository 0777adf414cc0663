"""The suction plate: its grasp sensor and its hold of one element per env.

Grasp (the paper's ray-cast sensor): a ray leaves the centre of the suction plate along its
approach axis (tcp z). When it meets the element's grasp face (its +z face, inside the face's
rectangle, within 60 degrees of the face normal) at a distance <= tau_pick, the element is grasped.
It is pulled onto the plate (the paper's attaching force) and then held rigidly against it: before
every physics substep the element's velocity is set so that it reaches its held pose relative to
the plate at the end of the substep (speed-capped, gravity included). The solver still resolves
the element's contacts, so a held element cannot pass through walls or slabs: it is stopped there
while the plate goes on. No joints are made at run time. The suction plate itself does not collide
with elements (its pads are compliant); every other link does.

The task owns which element each env works on and when a grasp counts; this module owns the
physics: `grasp_ray` (pure), `SuctionGripper.grasp` once per control step, and
`SuctionGripper.hold` before every physics substep. On physx_cpu (one env) the hold runs on
SAPIEN's own poses with numpy; on physx_cuda it is batched on the device.
"""

from __future__ import annotations

import numpy as np
import sapien
import torch

from mani_skill.utils.structs import Actor, Link

from ms_construction.rotations import pose_inv, pose_mul, qaxis, qconj, qmat, qmul, quat_to_rotvec, quat_z

PLATE_ELEMENT_COLLISION_BIT = 29
"""collision group 2 bit shared by the suction plate and the elements: they never collide."""
MAX_GRASP_INCIDENCE_DEG = 60.0
HOLD_MAX_SPEED = 3.0
"""m/s; the pull onto the plate and the tracking of a held element are capped at this speed."""
HOLD_MAX_ANGULAR_SPEED = 10.0
"""rad/s."""
_COS_MAX_INCIDENCE = float(np.cos(np.deg2rad(MAX_GRASP_INCIDENCE_DEG)))


def grasp_ray(tcp_in_el: torch.Tensor, size: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(distance along the plate's ray to the grasp face, whether the ray hits the face), given the
    tcp's raw pose [n, 7] in the element's frame and the element's size [n, 3].

    Distance is +inf where the ray misses the face or meets it from behind or too obliquely."""
    p = tcp_in_el[:, :3]
    d = qaxis(tcp_in_el[:, 3:], 2)  # the ray: the tcp's z axis, in the element frame
    face_z = size[:, 2] / 2
    facing = d[:, 2] <= -_COS_MAX_INCIDENCE
    above = p[:, 2] >= face_z - 1e-4
    dist = (p[:, 2] - face_z) / (-d[:, 2]).clamp(min=1e-6)
    hit = p[:, :2] + dist[:, None] * d[:, :2]
    ok = facing & above & (hit.abs() <= size[:, :2] / 2).all(-1)
    return torch.where(ok, dist, torch.full_like(dist, float("inf"))), ok


REACH_MARGIN = 0.01
"""m; `out_of_reach`'s margin over its bound, for float rounding."""


def out_of_reach(tcp_from_element: np.ndarray, half_diagonal: float, tau_pick: float) -> bool:
    """Whether no grasp can happen with the tcp at `tcp_from_element` (world vector from the element's
    centre): a grasp needs the ray to meet the grasp face within tau_pick, and every point of the face
    lies within the element's half-diagonal of its centre. A cheap test that spares physx_cpu the ray
    (a tenth of a step) while the plate is away from the element, with the same result."""
    return float(np.dot(tcp_from_element, tcp_from_element)) > (tau_pick + half_diagonal + REACH_MARGIN) ** 2


def _clip_norm(v: torch.Tensor, max_norm: float) -> torch.Tensor:
    n = torch.linalg.norm(v, dim=-1, keepdim=True)
    return v * torch.clamp(max_norm / n.clamp(min=1e-9), max=1.0)


def _clip_norm_np(v: np.ndarray, max_norm: float) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v * min(1.0, max_norm / max(n, 1e-9))


class SuctionGripper:
    """Whether each env's element is held, where on the plate, and the hold that keeps it there."""

    def __init__(self, tcp: Link, num_envs: int, device: torch.device, gravity, sim_freq: int, gpu: bool):
        self.tcp = tcp
        self.gpu = gpu
        self.dt = 1.0 / sim_freq
        self.held = torch.zeros(num_envs, dtype=torch.bool, device=device)
        """[n] the element is on the plate."""
        self.hold_pose_in_tcp = torch.zeros(num_envs, 7, device=device)
        """[n, 7] raw pose of the held element in the tcp frame (set at grasp)."""
        self.hold_pose_in_tcp[:, 3] = 1
        self._gravity = torch.tensor(gravity, dtype=torch.float32, device=device)
        self._gravity_np = np.asarray(gravity, np.float32)

    def reset(self, env_idx: torch.Tensor, nominal_hold: torch.Tensor) -> None:
        """At an episode's start: nothing held, and the hold of the last episode's grasp replaced by `nominal_hold`
        [len(env_idx), 7] (the element unturned on the plate), so that nothing read before the grasp (the env's
        `plate_turn`) depends on the episode before."""
        self.held[env_idx] = False
        self.hold_pose_in_tcp[env_idx] = nominal_hold

    def tcp_in_element(self, element: Actor) -> torch.Tensor:
        """Raw pose [n, 7] of the plate's tcp in the element's frame."""
        return pose_mul(pose_inv(element.pose.raw_pose), self.tcp.pose.raw_pose)

    def grasp(self, element: Actor, grasp_in_el: torch.Tensor, size: torch.Tensor, kind: torch.Tensor,
              tau_pick: torch.Tensor) -> torch.Tensor:
        """Grasp where the ray meets the face within tau_pick and nothing is held yet; returns
        which envs grasped now. Per element kind (indexed by `kind` [n]): `grasp_in_el` [kinds, 7],
        the tcp's pose at grasp in the element frame, and `size` [kinds, 3]. The held pose puts the
        grasp face against the plate, keeping the element's current rotation about the plate's
        axis: the pull does not spin it."""
        if not self.gpu and bool(self.held[0]):  # physx_cpu's one env holds already: no ray to cast
            return torch.zeros_like(self.held)
        grasp_in_el, size = grasp_in_el[kind], size[kind]
        if not self.gpu and out_of_reach(self.tcp._objs[0].entity_pose.p - element._bodies[0].entity.pose.p,
                                         float(torch.linalg.norm(size[0])) / 2, float(tau_pick[0])):
            return torch.zeros_like(self.held)  # physx_cpu: no ray to cast either
        tcp_in_el = self.tcp_in_element(element)
        dist, _ = grasp_ray(tcp_in_el, size)
        grasp_now = ~self.held & (dist <= tau_pick)
        if self.gpu or bool(grasp_now.any()):  # on the GPU a host sync costs more than the maths
            m = qmat(qmul(qconj(grasp_in_el[:, 3:]), tcp_in_el[:, 3:]))
            psi = torch.rad2deg(torch.atan2(m[:, 1, 0], m[:, 0, 0]))
            held_tcp_in_el = torch.cat([grasp_in_el[:, :3], qmul(grasp_in_el[:, 3:], quat_z(psi))], -1)
            self.hold_pose_in_tcp = torch.where(grasp_now[:, None], pose_inv(held_tcp_in_el), self.hold_pose_in_tcp)
            self.held |= grasp_now
        return grasp_now

    def hold(self, element: Actor, scene, first_substep: bool) -> None:
        """Before a physics substep: set the held elements' velocities so that each reaches its
        pose on the plate by the substep's end (it stays a dynamic body: it collides)."""
        if not self.gpu:
            if bool(self.held[0]):
                body = element._bodies[0]
                v, w = self.velocities_cpu(element)
                body.set_linear_velocity(v)
                body.set_angular_velocity(w)
            return
        if not first_substep:
            # the hold reads the element's pose and velocity and the tcp link's: fetch those alone,
            # not ManiSkill's full _gpu_fetch_all (joint positions, velocities, accelerations and
            # targets too), which the control step does anyway after its last substep
            scene.px.gpu_fetch_rigid_dynamic_data()
            scene.px.gpu_fetch_articulation_link_pose()
            scene.px.gpu_fetch_articulation_link_velocity()
        v, w = self.velocities(element)
        held = self.held[:, None]
        element.set_linear_velocity(torch.where(held, v, element.linear_velocity))
        element.set_angular_velocity(torch.where(held, w, element.angular_velocity))
        scene.px.gpu_apply_rigid_dynamic_data()

    def velocities(self, element: Actor) -> tuple[torch.Tensor, torch.Tensor]:
        """Linear and angular velocities [n, 3] that take each element to its held pose this substep."""
        tcp_pose, el_pose = self.tcp.pose.raw_pose, element.pose.raw_pose
        target = pose_mul(tcp_pose, self.hold_pose_in_tcp)
        # feed-forward: the held point moves with the plate; feedback: close the error this substep;
        # PhysX adds g*dt to the velocity before integrating the position
        w_tcp = self.tcp.angular_velocity
        v = self.tcp.linear_velocity + torch.cross(w_tcp, target[:, :3] - tcp_pose[:, :3], dim=-1)
        v = v + (target[:, :3] - el_pose[:, :3]) / self.dt - self._gravity * self.dt
        w = w_tcp + quat_to_rotvec(qmul(target[:, 3:], qconj(el_pose[:, 3:]))) / self.dt
        return _clip_norm(v, HOLD_MAX_SPEED), _clip_norm(w, HOLD_MAX_ANGULAR_SPEED)

    def velocities_cpu(self, element: Actor) -> tuple[np.ndarray, np.ndarray]:
        """`velocities` of the one physx_cpu env, computed on SAPIEN's own poses and numpy vectors:
        the same formula without a tensor round trip, which made the hold cost several times the
        physics substep it precedes (docs/BENCHMARKS.md, the "held" column)."""
        link, body = self.tcp._objs[0], element._bodies[0]
        tcp, el = link.entity_pose, body.entity.pose
        h = self.hold_pose_in_tcp[0].numpy()
        target = tcp * sapien.Pose(h[:3], h[3:])
        w_tcp = link.angular_velocity
        r = target.p - tcp.p
        lever = np.array([w_tcp[1] * r[2] - w_tcp[2] * r[1], w_tcp[2] * r[0] - w_tcp[0] * r[2],
                          w_tcp[0] * r[1] - w_tcp[1] * r[0]])  # w x r (np.cross costs more than the physics here)
        v = link.linear_velocity + lever + (target.p - el.p) / self.dt - self._gravity_np * self.dt
        q = (sapien.Pose(q=target.q) * sapien.Pose(q=el.q).inv()).q  # target rotation * element rotation^-1
        q = -q if q[0] < 0 else q
        s = float(np.linalg.norm(q[1:]))
        w = w_tcp + (q[1:] * (2 * np.arctan2(s, q[0]) / s if s > 1e-8 else 2.0)) / self.dt
        return _clip_norm_np(v, HOLD_MAX_SPEED), _clip_norm_np(w, HOLD_MAX_ANGULAR_SPEED)
