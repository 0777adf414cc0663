"""The joint-space geometry of a carry, as batched tensors: what the dense reward measures and the start states pose.

Everything here comes from inverse kinematics of the site's poses and collision checks on its model
(ms_construction/goal_configurations.py), for every task type and goal slot alike; no demonstrations, and nothing
names a slot, an opening or a turret side:

- the installation configurations of each goal slot (the carry's end), cut, where a slot is the mirror image of
  another in the arm's plane y = 0, to the wrist branch that mirrors its twin's (`mirror_branch_mask`);
- the table grasp configurations of each task type, one per turret side (the reach's end);
- the start paths of each goal slot (`goal_configurations.StartPaths`): collision-checked joint paths from each
  installation configuration out to the staging table, one per turret side, a planned via where the direct ones
  run into the site. The turret sides a slot's usable paths leave from are the sides its element is reached and
  grasped from (`path_sides`); the carry is measured along the grasp side's paths (`project`). From the sides a slot
  has no usable path from, its detours (a planned via each). Among a site's obstacles, each episode has its own
  (`episode_ways`, `EpisodeWays`): a turret side whose usable paths they block all of gets one back through a via
  searched around them at reset; where none is found and no usable path is clear, the reward measures along the
  detours they leave clear (`usable`, `clear_ways`).

`CarryGeometry.project` is the one projection per step the reward and the observation share: it is the cost of a
dense-reward step, so it works on per-slot constants gathered in two index operations.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Optional

import numpy as np
import torch

from ms_construction.goal_configurations import (install_configurations, lift_configurations, mirror_branch_mask,
                                                  mirror_twins, start_paths, symmetry_period)
from ms_construction.parameters import ELEMENT_KINDS

JOINT_MIRROR_SIGNS = (-1.0, 1.0, 1.0, -1.0, 1.0, -1.0)
"""How each arm joint turns in the mirror image of the arm in its base's plane y = 0: joints 1, 4 and 6 turn about
axes in that plane (z, x, x) and turn the other way, joints 2, 3 and 5 about axes across it (y) the same way; every
link's offsets lie in the plane (assets/arm/construction_arm.urdf), so the mirrored arm is the arm at these signs."""

PATH_DEVIATION_WEIGHT = 3.0
"""the carry counts each radian off a start path this many times: cutting across to the goal (or to a later point
of the path) costs more than going along the path, whose length from a lift above the table to the goal is up to
about twice the straight joint move's."""
VIA_DEVIATION_WEIGHT = 25.0
"""each radian off a path through a planned via, from the lift above the table in, counts this many times: that
detour exists because cutting across runs the element into the site. At PATH_DEVIATION_WEIGHT a window carried
into the opening beside its own measured about as near its goal as the via, and the cut across nearer than the lift;
at this weight both measure farther than the path's table end (`python -m experiments.via_landscape`)."""
PATH_LOOKAHEAD = 0.5
"""rad; `path_offset` points this far (joint-space, L1) along the path ahead of the arm's nearest point on it."""


def wrap(x: torch.Tensor, period: torch.Tensor) -> torch.Tensor:
    """x wrapped into [-period / 2, period / 2)."""
    return torch.remainder(x + period / 2, period) - period / 2


def path_points(waypoints: torch.Tensor, fraction: torch.Tensor) -> torch.Tensor:
    """[m, 6]: the configurations `fraction` [m] of the way along polylines of joint configurations [m, p, 6], by their
    summed joint-space (L1) length (goal_configurations.path_point, batched)."""
    seg = (waypoints[:, 1:] - waypoints[:, :-1]).abs().sum(-1)  # [m, p - 1]
    at = (fraction * seg.sum(-1))[:, None]
    start = torch.cumsum(seg, -1) - seg
    w = ((at - start) / seg.clamp(min=1e-9)).clamp(0, 1) * (seg > 0)  # how far along each segment
    return waypoints[:, 0] + (w[..., None] * (waypoints[:, 1:] - waypoints[:, :-1])).sum(1)


def _project(qpos: torch.Tensor, turn: torch.Tensor, period: torch.Tensor, segments: torch.Tensor,
             vertices: torch.Tensor, usable: torch.Tensor, kept: torch.Tensor, side: torch.Tensor, lookahead: float):
    """`CarryGeometry.project` on the goal slots' constants (segments [n, M, S, 10]: the step to the next vertex, the
    inverse of its squared length over joints 1-5, its L1 length, the path's length before it, its weight; vertices
    [n, M, P, 8]: the configuration, the path's length before it, its weight; usable and kept [n, M]): the carry
    distance [n], the path's length from the installation to the point it is measured from [n], the joint move to the
    nearest kept installation [n, 6] and the one to the point `lookahead` ahead of it along its path [n, 6]. TorchScript (`_scripted`): at
    one env per process a dense-reward step is dominated by the per-operation overhead of these few hundred numbers."""
    q = qpos.clone()
    q[:, 5] -= turn
    half = (period / 2)[:, None, None]
    period = period[:, None, None]
    rel = q[:, None, None, :] - vertices[..., :6]  # [n, M, P, 6]
    off_vertex = rel[..., :5].abs().sum(-1) + (torch.remainder(rel[..., 5] + half, period) - half).abs()
    seg = segments[..., :6]
    start = rel[:, :, :-1]  # from each segment's start
    t = ((start[..., :5] * seg[..., :5]).sum(-1) * segments[..., 6]).clamp(0.0, 1.0)
    diff = start - t[..., None] * seg
    off_segment = diff[..., :5].abs().sum(-1) + (torch.remainder(diff[..., 5] + half, period) - half).abs()
    # only along the paths from the grasp side (their index: configuration * 2 + side), where the slot has any
    m = usable.shape[1]
    on_side = torch.remainder(torch.arange(m, device=usable.device), 2)[None] == side[:, None]
    both = usable & on_side
    usable = torch.where(both.any(-1, keepdim=True), both, usable)[..., None]
    along = segments[..., 8] + t * segments[..., 7]  # the path's length from the installation to each nearest point
    inf = torch.full_like(along, float("inf"))
    cost = torch.cat([torch.where(usable, segments[..., 9] * off_segment + along, inf).flatten(1),
                      torch.where(usable, vertices[..., 7] * off_vertex + vertices[..., 6], inf[..., :1]).flatten(1)], 1)
    at_all = torch.cat([along.flatten(1), vertices[..., 6].flatten(1)], 1)
    distance, best = cost.min(-1)
    s = seg.shape[2]
    path = torch.where(best < m * s, torch.div(best, s, rounding_mode="floor"),
                       torch.div(best - m * s, s + 1, rounding_mode="floor"))
    rows = torch.arange(q.shape[0], device=q.device)
    # the installations are the paths' first vertices: the nearest kept one by the same joint-space measure
    install = torch.where(kept, off_vertex[..., 0], inf[..., 0]).argmin(-1)
    to_install = -rel[rows, install, 0]
    to_install[:, 5] = torch.remainder(to_install[:, 5] + half[:, 0, 0], period[:, 0, 0]) - half[:, 0, 0]
    at = at_all.gather(1, best[:, None])[:, 0]
    # the point `lookahead` nearer the installation along the same path (goal_configurations.path_point, batched)
    chosen = segments[rows, path]  # [n, S, 10]
    length = chosen[..., 7]
    reach = (at - lookahead).clamp(min=0.0)[:, None]
    frac = ((reach - chosen[..., 8]) / length.clamp(min=1e-9)).clamp(0.0, 1.0) * (length > 0)
    target = vertices[rows, path, 0, :6] + (frac[..., None] * chosen[..., :6]).sum(1)
    to_path = target - q  # q: joint 6 already shifted by the turn
    to_path[:, 5] = torch.remainder(to_path[:, 5] + half[:, 0, 0], period[:, 0, 0]) - half[:, 0, 0]
    return distance, at, to_install, to_path


def path_tables(waypoints: torch.Tensor, via: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The projection's constants (`_project`) of start paths `waypoints` [..., M, P, 6] whose corner is a planned via
    where `via` [..., M]: segments [..., M, P - 1, 10] and vertices [..., M, P, 8]."""
    seg = waypoints[..., 1:, :] - waypoints[..., :-1, :]
    length = seg.abs().sum(-1)
    before = torch.cumsum(length, -1) - length  # the path's length from the installation to each segment
    # from the lift in, a planned via's path counts VIA_DEVIATION_WEIGHT; the table's segment keeps the lenient weight
    # (the grasp's posture need not match the path's, and nothing lies across)
    not_table = torch.arange(seg.shape[-2], device=seg.device) < seg.shape[-2] - 1
    weight = torch.where(via[..., None] & not_table, VIA_DEVIATION_WEIGHT, PATH_DEVIATION_WEIGHT)
    # a vertex is the end of the segments either side of it: it counts at the lighter of their weights
    vertex_weight = torch.minimum(torch.cat([weight[..., :1], weight], -1), torch.cat([weight, weight[..., -1:]], -1))
    vertex_before = torch.cat([torch.zeros_like(length[..., :1]), torch.cumsum(length, -1)], -1)
    inv = 1.0 / (seg[..., :5] ** 2).sum(-1).clamp(min=1e-9)
    return (torch.cat([seg, inv[..., None], length[..., None], before[..., None], weight[..., None]], -1),
            torch.cat([waypoints, vertex_before[..., None], vertex_weight[..., None]], -1))


@functools.lru_cache(maxsize=None)
def _scripted(fn):
    """`fn` compiled by TorchScript, once per process (its interpreter runs a small op several times faster than
    Python does)."""
    return torch.jit.script(fn)


@dataclass
class Projection:
    """The arm's nearest point on its goal slot's start paths, as the carry measures it, and the joint moves the
    observation offers."""

    distance: torch.Tensor
    """[n] rad: the carry distance (`CarryGeometry.project`)."""
    at: torch.Tensor
    """[n] rad: the length of the path it is measured along, from the installation to the point it is measured from."""
    install_offset: torch.Tensor
    """[n, 6] rad: the joint move to the nearest installation configuration."""
    path_offset: torch.Tensor
    """[n, 6] rad: the joint move to the point PATH_LOOKAHEAD ahead, toward the installation, of the point the carry is
    measured from, along its path (the installation itself within PATH_LOOKAHEAD of it): which way the carry falls
    from here."""


@dataclass
class EpisodeWays:
    """The start paths of each env's goal slot as one episode among a site's obstacles has them
    (`CarryGeometry.episode_ways`)."""

    clear: torch.Tensor
    """[n, M] bool: which keep clear of the obstacles (`SiteObstacles.clear_paths`)."""
    searched: torch.Tensor
    """[n, M] bool: the paths whose via was searched for this episode (goal_configurations.search_via): a turret side
    whose usable paths the obstacles block all of gets one of them back, clear, through a via around them."""
    waypoints: torch.Tensor
    """[n, M, P, 6]: the slot's start paths, the searched ones through their via."""
    free: torch.Tensor
    """[n, M]: their clear fraction on the site (StartPaths.free; 1 for a searched one)."""
    segments: torch.Tensor
    vertices: torch.Tensor
    """the projection's constants of `waypoints` (`path_tables`)."""
    sides: torch.Tensor
    """[n, 2] bool: the turret sides the reach pays for (`CarryGeometry.path_sides`)."""
    carried: torch.Tensor
    """[n, 3, M] bool: the paths the carry is measured along after a grasp from turret side 0 (+pi), 1 (-pi), and
    before a grasp (`CarryGeometry.carry_paths`; the last row is the one side -1 indexes). Fixed for the episode, so
    worked out once rather than at every step."""


class CarryGeometry:
    """The tables of the module docstring on a device, and the measures taken on them. Built once per env; the
    tables are computed once per process (a few seconds, lru-cached in goal_configurations)."""

    def __init__(self, device: torch.device):
        self.device = device
        f32 = dict(dtype=torch.float32, device=device)
        self.period = torch.tensor([symmetry_period(k) for k in ELEMENT_KINDS], **f32)
        self.kept = mirror_branch_mask(JOINT_MIRROR_SIGNS)  # [kinds, slots, configurations]
        twins = mirror_twins()
        # a configuration not kept is replaced by its slot's first kept one (the table repeats them already)
        table = install_configurations().copy()
        # how far joint 6 of a mirrored slot's kept installation is from its twin's mirror image (half a turn for a
        # window, whose head stays up in the mirror; 0 for a slot without a twin)
        turn = np.zeros(twins.shape, dtype=np.float32)
        for k, slot in zip(*np.nonzero(twins >= 0)):
            kept_q = table[k, slot, self.kept[k, slot].argmax()]
            turn[k, slot] = kept_q[5] - JOINT_MIRROR_SIGNS[5] * table[k, twins[k, slot], 0, 5]
        self.mirror_turn = torch.tensor(turn, **f32)
        first = self.kept.argmax(-1)[..., None, None].repeat(table.shape[-1], -1)
        self.install_q = torch.tensor(np.where(self.kept[..., None], table, np.take_along_axis(table, first, 2)), **f32)
        self.table_q = torch.tensor(lift_configurations(0.0), **f32)  # [kinds, 2 turret sides, 6]
        self._paths: Optional[dict] = None
        self._inf = torch.tensor(torch.inf, device=device)

    # ------------------------------------------------------------------------------------------------- #
    # start paths
    # ------------------------------------------------------------------------------------------------- #
    @property
    def paths(self) -> dict:
        """The start paths as tensors [kinds, slots, configurations x 2 sides, ...] (their index: configuration * 2 +
        side, side 0 leaving the table at turret +pi, 1 at -pi), and the projection's per-slot constants."""
        if self._paths is None:
            sp = start_paths()
            f32 = dict(dtype=torch.float32, device=self.device)
            k, s = sp.waypoints.shape[:2]
            w = torch.tensor(sp.waypoints, **f32).flatten(2, 3)  # [k, s, M, P, 6]
            usable = torch.tensor(sp.usable & self.kept[..., None], device=self.device).flatten(2)  # [k, s, M]
            planned = torch.tensor(sp.planned, device=self.device).flatten(2)
            detour = torch.tensor(sp.detour & self.kept[..., None], device=self.device).flatten(2)
            segments, vertices = path_tables(w, planned | detour)
            sides = usable.view(k, s, -1, 2).any(2)
            kept = torch.tensor(self.kept, device=self.device).repeat_interleave(2, -1)  # [k, s, M]
            self._paths = dict(
                waypoints=w, free=torch.tensor(sp.free, **f32).flatten(2), usable=usable, planned=planned, detour=detour, kept=kept,
                sides=sides | ~sides.any(-1, keepdim=True),
                segments=segments, vertices=vertices)
        return self._paths

    def episode_ways(self, task: torch.Tensor, slot: torch.Tensor, clear: torch.Tensor,
                     vias: dict[tuple[int, int], np.ndarray]) -> EpisodeWays:
        """The start paths of each env's goal slot (`task`, `slot` [n]) for an episode among obstacles: `clear` [n, M]
        as checked, and each path (env, index) of `vias` through that via configuration instead of its corner, clear."""
        p = self.paths
        waypoints, free = p["waypoints"][task, slot].clone(), p["free"][task, slot].clone()
        via, clear = (p["planned"] | p["detour"])[task, slot].clone(), clear.clone()
        searched = torch.zeros_like(clear)
        for (env, path), q in vias.items():
            waypoints[env, path, 2] = torch.as_tensor(q, dtype=waypoints.dtype, device=self.device)
            free[env, path], clear[env, path], via[env, path], searched[env, path] = 1.0, True, True, True
        ways = self.usable(task, slot, clear)
        sides = ways.view(len(task), -1, 2).any(1)
        sides = torch.where(sides.any(-1, keepdim=True), sides, True)
        # after a grasp from one side, that side's usable paths clear of the obstacles where any is, else its clear
        # detours, else its usable paths even though blocked: the turret cannot cross to the other side holding the
        # element, so another side's clear way is no way for it; before a grasp, every way the reward measures along
        on_side = torch.arange(ways.shape[-1], device=self.device) % 2 == torch.arange(2, device=self.device)[:, None]
        usable, detour = (self.paths[key][task, slot][:, None] & on_side for key in ("usable", "detour"))  # [n, 2, M]
        grasped = usable & clear[:, None]
        for fallback in (detour & clear[:, None], usable):
            grasped = torch.where(grasped.any(-1, keepdim=True), grasped, fallback)
        grasped = torch.where(grasped.any(-1, keepdim=True), grasped, ways[:, None])
        return EpisodeWays(clear, searched, waypoints, free, *path_tables(waypoints, via), sides,
                           torch.cat([grasped, ways[:, None]], 1))

    def clear_ways(self, task: torch.Tensor, slot: torch.Tensor, clear: torch.Tensor) -> torch.Tensor:
        """[n, M] bool: the start paths of each env's goal slot that keep clear of a site's obstacles (`clear` [n, M],
        `SiteObstacles.clear_paths`): its usable ones that are clear, where any is; else its detours that are clear
        (StartPaths.detour: from the turret sides it has no usable path from); none where neither is."""
        usable = self.paths["usable"][task, slot] & clear
        return torch.where(usable.any(-1, keepdim=True), usable, self.paths["detour"][task, slot] & clear)

    def usable(self, task: torch.Tensor, slot: torch.Tensor, clear: Optional[torch.Tensor] = None) -> torch.Tensor:
        """[n, M] bool: the start paths the dense reward measures along for each env's goal slot: its usable ones;
        with `clear` [n, M] (the paths clear of a site's obstacles), its `clear_ways` where it has any, and its usable
        ones where the obstacles block every way."""
        usable = self.paths["usable"][task, slot]
        if clear is None:
            return usable
        ways = self.clear_ways(task, slot, clear)
        return torch.where(ways.any(-1, keepdim=True), ways, usable)

    def carry_paths(self, task: torch.Tensor, slot: torch.Tensor, side: torch.Tensor,
                    ways: Optional[EpisodeWays] = None) -> torch.Tensor:
        """[n, M] bool: the paths the carry is measured along: `usable`; among a site's obstacles (`ways`), after a
        grasp from turret side `side` [n] (0: +pi, 1: -pi; -1: none), that side's usable paths clear of them where any
        is, else its clear detours, else its usable paths even though blocked (`EpisodeWays.carried`)."""
        if ways is None:
            return self.paths["usable"][task, slot]
        return ways.carried[torch.arange(len(side), device=side.device), side]

    def path_sides(self, task: torch.Tensor, slot: torch.Tensor, ways: Optional[EpisodeWays] = None) -> torch.Tensor:
        """[n, 2] bool: the turret sides (+pi, -pi) a usable start path (`usable`; among a site's obstacles, `ways`:
        one the reward measures along) of each goal slot leaves the table from; both for a slot without any."""
        return self.paths["sides"][task, slot] if ways is None else ways.sides

    def project(self, qpos: torch.Tensor, turn: torch.Tensor, task: torch.Tensor, slot: torch.Tensor,
                side: torch.Tensor, ways: Optional[EpisodeWays] = None) -> Projection:
        """How far the arm (`qpos` [n, 6], its element turned `turn` [n] on the plate) is from holding its element
        installed along the nearest usable start path of its goal slot: the least, over the points of the paths,
        of the path's weight (PATH_DEVIATION_WEIGHT, VIA_DEVIATION_WEIGHT) times the joint-space (L1) distance to
        the point plus the path's length from there to the installation; joint 6 shifted by the turn and compared
        modulo the element's symmetry. Only along the paths that leave the table from the turret side `side` [n]
        (0: +pi, 1: -pi, -1: none) the element was grasped from, where the slot has any: the turret cannot cross to
        the other side holding it. The candidates are each segment's nearest point by joints 1-5 (joint 6 is
        compared modulo a period, which a projection cannot take) and every vertex. Among a site's obstacles (`ways`),
        along the episode's paths clear of them, the grasp side's first (`carry_paths`), a searched via where one is.
        """
        p = self.paths
        segments, vertices = ((p["segments"][task, slot], p["vertices"][task, slot]) if ways is None
                              else (ways.segments, ways.vertices))
        return Projection(*_scripted(_project)(
            qpos, turn, self.period[task], segments, vertices,
            self.carry_paths(task, slot, side, ways), p["kept"][task, slot], side,
            PATH_LOOKAHEAD))

    def reach_distance(self, qpos: torch.Tensor, task: torch.Tensor, slot: torch.Tensor,
                       ways: Optional[EpisodeWays] = None) -> torch.Tensor:
        """[n] rad; how far the arm is, in joint space (joints 1-5 summed: the plate's roll does not matter to the
        suction grasp, which keeps the element's turn), from the nearest configuration that grasps its element where
        it lies on the staging table, on a turret side that a usable start path of its goal slot leaves the table
        from (`path_sides`): an element grasped from the other side has no collision-free way to its goal along
        them."""
        distance = (self.table_q[task][..., :5] - qpos[:, None, :5]).abs().sum(-1)  # [n, 2 turret sides]
        return torch.where(self.path_sides(task, slot, ways), distance, torch.inf).amin(-1)
