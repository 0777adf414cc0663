"""The construction arm: a 6-DoF industrial arm on a pedestal with a suction plate, as a URDF.

Kinematics of a common industrial layout (turret yaw, shoulder and elbow pitch with a shoulder
offset, spherical-ish wrist roll-pitch-roll), about 1.8 m reach, sized for a 15 kg element plus a
7 kg suction plate. Collision geometry is boxes and cylinders only.

Effort limits follow the paper's 400 N tool force limit: each joint can exert 400 N at the tool
along its longest lever, on top of holding the arm's own links and the plate stretched out
horizontally (the worst case for gravity). `scripts/build_assets.py` writes the URDF (and an SRDF
for motion planners) and records the numbers in the manifest.
"""

from __future__ import annotations

import numpy as np

from ms_construction.parameters import G, TOOL_FORCE_LIMIT, ArmParams


def _box_inertia(m, sx, sy, sz):
    return (m / 12 * (sy**2 + sz**2), m / 12 * (sx**2 + sz**2), m / 12 * (sx**2 + sy**2))


def _cyl_inertia(m, r, h, axis):
    """Principal inertia of a solid cylinder whose axis is 'x', 'y' or 'z'."""
    ia, it = m * r**2 / 2, m * (3 * r**2 + h**2) / 12
    return tuple(ia if a == axis else it for a in "xyz")


def _links(p: ArmParams):
    """(name, parent joint, mass, com, inertia diag, shapes) for every moving link.

    A shape is ('box', size, xyz, rpy) or ('cylinder', (radius, length), xyz, rpy)."""
    sx, sz = p.shoulder_offset
    f1, f2 = p.forearm
    m = p.masses
    half_pi = np.pi / 2
    links = [
        ("turret", m[0], (0.05, 0, 0.2), _box_inertia(m[0], 0.45, 0.4, 0.45),
         [("cylinder", (0.2, 0.2), (0, 0, 0.1), (0, 0, 0)), ("box", (0.3, 0.36, 0.25), (0.1, 0, 0.3), (0, 0, 0))]),
        ("upper_arm", m[1], (0, 0, p.upper_arm / 2), _box_inertia(m[1], 0.16, 0.2, p.upper_arm),
         [("box", (0.16, 0.2, p.upper_arm - 0.14), (0, 0, p.upper_arm / 2), (0, 0, 0)),
          ("cylinder", (0.1, 0.24), (0, 0, p.upper_arm), (half_pi, 0, 0))]),
        ("forearm", m[2], (0.1, 0, 0), _box_inertia(m[2], f1 + 0.12, 0.16, 0.16),
         [("box", (f1 - 0.05, 0.16, 0.16), (f1 / 2 + 0.015, 0, 0), (0, 0, 0)),
          ("box", (0.12, 0.14, 0.14), (-0.08, 0, 0), (0, 0, 0))]),
        ("forearm_roll", m[3], (f2 / 2, 0, 0), _cyl_inertia(m[3], 0.065, f2, "x"),
         [("cylinder", (0.065, f2 - 0.12), (f2 / 2 - 0.04, 0, 0), (0, half_pi, 0))]),
        ("wrist", m[4], (0.04, 0, 0), _box_inertia(m[4], 0.14, 0.14, 0.12),
         [("cylinder", (0.06, 0.13), (0, 0, 0), (half_pi, 0, 0)), ("box", (0.06, 0.1, 0.1), (0.055, 0, 0), (0, 0, 0))]),
        ("flange", m[5], (0.02, 0, 0), _cyl_inertia(m[5], 0.05, 0.04, "x"),
         [("cylinder", (0.05, 0.035), (0.0175 + 0.0025, 0, 0), (0, half_pi, 0))]),
    ]
    return links


def _joints(p: ArmParams):
    """(name, parent, child, xyz, axis) of the six revolute joints."""
    sx, sz = p.shoulder_offset
    f1, f2 = p.forearm
    return [
        ("joint1", "base_link", "turret", (0, 0, p.pedestal_height), (0, 0, 1)),
        ("joint2", "turret", "upper_arm", (sx, 0, sz), (0, 1, 0)),
        ("joint3", "upper_arm", "forearm", (0, 0, p.upper_arm), (0, 1, 0)),
        ("joint4", "forearm", "forearm_roll", (f1, 0, 0), (1, 0, 0)),
        ("joint5", "forearm_roll", "wrist", (f2, 0, 0), (0, 1, 0)),
        ("joint6", "wrist", "flange", (p.wrist_to_flange, 0, 0), (1, 0, 0)),
    ]


def effort_limits(p: ArmParams) -> list[float]:
    """Nm per joint: 400 N at the tool along the joint's longest lever + the worst-case gravity
    torque of the links it carries (arm stretched horizontally), rounded up to 10 Nm."""
    sx, sz = p.shoulder_offset
    f1, f2 = p.forearm
    # distance along the stretched arm from the shoulder to each moving mass and to the tcp
    reach_tcp = p.upper_arm + f1 + f2 + p.wrist_to_tcp
    pos = {
        "upper_arm": p.upper_arm / 2,
        "forearm": p.upper_arm + 0.1,
        "forearm_roll": p.upper_arm + f1 + f2 / 2,
        "wrist": p.upper_arm + f1 + f2 + 0.04,
        "flange": p.upper_arm + f1 + f2 + p.wrist_to_flange + 0.02,
        "plate": reach_tcp - p.plate_thickness / 2,
    }
    mass = dict(zip(["upper_arm", "forearm", "forearm_roll", "wrist", "flange"], p.masses[1:]), plate=p.plate_mass)
    joint_pos = [None, 0.0, p.upper_arm, p.upper_arm + f1, p.upper_arm + f1 + f2, None]
    limits = []
    for i in range(6):
        if i in (0, 5):
            # yaw about a vertical axis and tool roll: no gravity torque; tool lever is the
            # horizontal reach (turret) or the plate's half diagonal (tool roll)
            lever = sx + reach_tcp if i == 0 else p.plate_size / np.sqrt(2)
            limits.append(TOOL_FORCE_LIMIT * lever)
            continue
        if i == 3:
            # forearm roll: gravity torque only from an off-axis load; tool lever = plate size
            limits.append(TOOL_FORCE_LIMIT * (p.wrist_to_tcp + p.plate_size / 2))
            continue
        j = joint_pos[i]
        grav = sum(G * mass[k] * (x - j) for k, x in pos.items() if x > j)
        limits.append(TOOL_FORCE_LIMIT * (reach_tcp - j) + grav)
    return [float(np.ceil(v / 10.0) * 10.0) for v in limits]


def _fmt(v) -> str:
    return " ".join(f"{float(x):.6g}" for x in v)


def _geometry(shape) -> str:
    kind, dims, _, _ = shape
    if kind == "box":
        return f'<box size="{_fmt(dims)}"/>'
    return f'<cylinder radius="{dims[0]:.6g}" length="{dims[1]:.6g}"/>'


def _link_xml(name, mass, com, inertia, shapes, color_name) -> str:
    out = [f'  <link name="{name}">',
           "    <inertial>",
           f'      <origin xyz="{_fmt(com)}" rpy="0 0 0"/>',
           f'      <mass value="{mass:.6g}"/>',
           f'      <inertia ixx="{inertia[0]:.6g}" ixy="0" ixz="0" iyy="{inertia[1]:.6g}" iyz="0" izz="{inertia[2]:.6g}"/>',
           "    </inertial>"]
    for tag in ("visual", "collision"):
        for shape in shapes:
            _, _, xyz, rpy = shape
            out.append(f"    <{tag}>")
            out.append(f'      <origin xyz="{_fmt(xyz)}" rpy="{_fmt(rpy)}"/>')
            out.append(f"      <geometry>{_geometry(shape)}</geometry>")
            if tag == "visual":
                out.append(f'      <material name="{color_name}"/>')
            out.append(f"    </{tag}>")
    out.append("  </link>")
    return "\n".join(out)


def arm_urdf(p: ArmParams = ArmParams()) -> str:
    """The arm's URDF text: base_link (pedestal), six moving links, suction_plate and tcp."""
    efforts = effort_limits(p)
    h = p.pedestal_height
    xml = ['<?xml version="1.0"?>',
           "<!-- generated by scripts/build_assets.py from ms_construction/build/arm_model.py: do not edit -->",
           '<robot name="construction_arm">',
           f'  <material name="arm"><color rgba="{_fmt(p.color)}"/></material>',
           '  <material name="dark"><color rgba="0.15 0.15 0.17 1"/></material>',
           '  <material name="pad"><color rgba="0.05 0.05 0.05 1"/></material>']
    xml.append(_link_xml("base_link", 150.0, (0, 0, h / 2), _cyl_inertia(150.0, 0.22, h, "z"),
                         [("cylinder", (0.22, h - 0.03), (0, 0, (h + 0.03) / 2), (0, 0, 0)),
                          ("box", (0.6, 0.6, 0.03), (0, 0, 0.015), (0, 0, 0))], "dark"))
    for name, mass, com, inertia, shapes in _links(p):
        xml.append(_link_xml(name, mass, com, inertia, shapes, "arm"))
    t = p.plate_thickness
    plate_inertia = _box_inertia(p.plate_mass, t, p.plate_size, p.plate_size)
    xml.append(_link_xml("suction_plate", p.plate_mass, (t / 2, 0, 0), plate_inertia,
                         [("box", (t, p.plate_size, p.plate_size), (t / 2, 0, 0), (0, 0, 0))], "pad"))
    xml.append('  <link name="tcp"/>')
    for (name, parent, child, xyz, axis), lo, hi, vel, eff in zip(_joints(p), p.lower, p.upper, p.velocity, efforts):
        xml.append(f'  <joint name="{name}" type="revolute">\n'
                   f'    <parent link="{parent}"/>\n    <child link="{child}"/>\n'
                   f'    <origin xyz="{_fmt(xyz)}" rpy="0 0 0"/>\n    <axis xyz="{_fmt(axis)}"/>\n'
                   f'    <limit lower="{lo:.6g}" upper="{hi:.6g}" velocity="{vel:.6g}" effort="{eff:.6g}"/>\n'
                   f'    <dynamics damping="0" friction="0"/>\n  </joint>')
    xml.append(f'  <joint name="plate_joint" type="fixed">\n    <parent link="flange"/>\n    <child link="suction_plate"/>\n'
               f'    <origin xyz="{p.flange_to_plate:.6g} 0 0" rpy="0 0 0"/>\n  </joint>')
    # tcp: centre of the plate's face, z axis pointing out of the plate (the approach direction)
    xml.append(f'  <joint name="tcp_joint" type="fixed">\n    <parent link="suction_plate"/>\n    <child link="tcp"/>\n'
               f'    <origin xyz="{t:.6g} 0 0" rpy="0 {np.pi / 2:.6g} 0"/>\n  </joint>')
    xml.append("</robot>\n")
    return "\n".join(xml)


def arm_srdf(p: ArmParams = ArmParams()) -> str:
    """The arm's SRDF text for motion planners (mplib): collisions between adjacent links disabled.

    The reason is "Adjacent", not "Default": SAPIEN's URDF loader reads an SRDF next to the URDF
    but applies only "Default" pairs, so the simulated arm's collisions stay exactly as they are
    (PhysX already ignores parent-child contacts)."""
    pairs = [(parent, child) for _, parent, child, _, _ in _joints(p)]
    pairs += [("flange", "suction_plate"), ("suction_plate", "tcp")]  # the fixed joints
    xml = ['<?xml version="1.0"?>',
           "<!-- generated by scripts/build_assets.py from ms_construction/build/arm_model.py: do not edit -->",
           '<robot name="construction_arm">']
    xml += [f'  <disable_collisions link1="{a}" link2="{b}" reason="Adjacent"/>' for a, b in pairs]
    xml.append("</robot>\n")
    return "\n".join(xml)
