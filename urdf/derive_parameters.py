"""Derive the inertial and drive parameters written in ``planar_arm.urdf``.

Every mass, centre of mass, inertia, effort limit, velocity limit, rotor inertia and gear
ratio in the URDF is computed here from the geometry and component data below. The script
is standalone (numpy only) so that it can be read and run without the project installed:

    python urdf/derive_parameters.py          # the table
    python urdf/derive_parameters.py --xml    # URDF snippets with every digit

Conventions: each link frame sits on its joint axis, the link extends along its own -y
axis, joint axes are +z, and the arm moves in the world x-y plane with gravity along -y
(paper eq. 18). Every component is centred on the arm's plane z = 0 (see README.md), so
centres of mass lie on the link's y axis and the inertia tensors are diagonal.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass

import numpy as np

# --- Geometry -------------------------------------------------------------------------
# Link lengths l1, l2 (joint to joint) and l3 (joint 3 to the fingertip contact point), m.
# Project default (docs/evidence/paper-notes.md, section 6): the paper does not print them.
LINK_LENGTHS: tuple[float, float, float] = (0.20, 0.20, 0.10)
# Plate thickness, m: 9.525 mm = 3/8 in (paper, Section VI-A).
PLATE_THICKNESS = 9.525e-3
# Plate width, m: 38.1 mm = 1.5 in flat bar (assumed; a common stock size).
PLATE_WIDTH = 38.1e-3
# Plate length beyond each joint axis, m: half the width, i.e. the material that surrounds
# the bearing bore (assumed). The last plate stops at the fingertip's centre instead.
PLATE_END_MARGIN = PLATE_WIDTH / 2
# Density of aluminium 6063-T5, kg/m^3 (2.69-2.70 g/cm^3 in the alloy's data sheets).
ALUMINIUM_DENSITY = 2700.0

# --- Drive unit: one per joint (paper: "three DC brushless servomotors", Micromo) -----
# Motor: Faulhaber (sold by Micromo) 2250 S 024 BX4, 22 mm brushless DC servomotor; values
# from its data sheet (24 V winding).
MOTOR_PART = "Faulhaber 2250 S 024 BX4"
MOTOR_MASS = 0.106  # kg ("weight 106 g").
MOTOR_ROTOR_INERTIA = 10.0e-7  # kg m^2 (10 g cm^2).
MOTOR_STALL_TORQUE = 0.149  # N m (149 mNm at 24 V): the peak the motor can produce.
MOTOR_CONTINUOUS_TORQUE = 0.023  # N m ("torque up to" 23 mNm, continuous operation).
MOTOR_NO_LOAD_SPEED = 6000.0 * 2.0 * math.pi / 60.0  # rad/s (6000 rpm at 24 V).
# Gearhead: three-stage planetary, 30-32 mm class (assumed; the paper does not name it).
GEARHEAD_PART = "3-stage planetary gearhead, 32 mm class"
GEARHEAD_MASS = 0.190  # kg (assumed, typical of the class).
GEARHEAD_EFFICIENCY = 0.70  # typical catalogue maximum for three planetary stages.
# Drive unit envelope as a solid cylinder on the joint axis (axis along z), m.
DRIVE_RADIUS = 0.016  # 32 mm gearhead diameter.
DRIVE_LENGTH = 0.110  # motor 50 mm + gearhead about 60 mm.

# --- Fingertip: silicone finger cover + FlexiForce A201 + sensor cup (paper VI-C) -------
# Modelled as a uniform solid sphere whose surface touches the contact point.
FINGERTIP_MASS = 0.030  # kg (assumed: cover ~9 g, sensor and lead ~1 g, cup ~20 g).
FINGERTIP_RADIUS = 0.0125  # m (25 mm diameter finger cover, assumed).

# --- Base: aluminium block behind joint 1, carrying joint 1's drive unit ----------------
BASE_BLOCK_SIZE: tuple[float, float, float] = (0.080, 0.080, 0.020)  # m (assumed).

# --- Task and sizing rules ---------------------------------------------------------------
GRAVITY = 9.81  # m/s^2, along world -y.
SENSOR_FULL_SCALE = 100.0  # N, FlexiForce A201 range used by the paper (Section VI-B).
PAPER_FORCE_REFERENCE = 5.0  # N, the paper's desired force (Section VII).
TASK_X_RANGE = (0.14, 0.21)  # m, fingertip x over the paper's tasks (wall near 0.15-0.20).
TASK_Y_RANGE = (-0.275, -0.225)  # m, y_d = -0.25 +- 0.025 (paper eq. 19).
TASK_THETA = math.pi / 2  # rad, link 3 horizontal, pointing at the wall (+x).
TASK_GRID = 15  # samples per task-region axis for the torque scan.
EFFORT_STEP = 5.0  # N m: effort limits are the required torque rounded up to this step.

JOINT_NAMES = ("joint1", "joint2", "joint3")
LINK_NAMES = ("link1", "link2", "link3")


@dataclass(frozen=True)
class Part:
    """A rigid component: mass, centre of mass in the link frame, inertia about its COM."""

    name: str
    mass: float
    position: np.ndarray
    inertia: np.ndarray


@dataclass(frozen=True)
class LinkInertial:
    """What a URDF ``<inertial>`` holds: mass, COM in the link frame, inertia about COM."""

    mass: float
    com: np.ndarray
    inertia: np.ndarray


def box_inertia(mass: float, size: tuple[float, float, float]) -> np.ndarray:
    """Returns the inertia of a uniform box about its centre, axes along its edges."""
    sx, sy, sz = size
    return mass / 12.0 * np.diag([sy**2 + sz**2, sx**2 + sz**2, sx**2 + sy**2])


def cylinder_inertia(mass: float, radius: float, length: float) -> np.ndarray:
    """Returns the inertia of a uniform solid cylinder (axis z) about its centre."""
    transverse = mass * (3.0 * radius**2 + length**2) / 12.0
    return np.diag([transverse, transverse, 0.5 * mass * radius**2])


def sphere_inertia(mass: float, radius: float) -> np.ndarray:
    """Returns the inertia of a uniform solid sphere about its centre."""
    return 0.4 * mass * radius**2 * np.eye(3)


def combine(parts: list[Part]) -> LinkInertial:
    """Sums parts into one rigid body (parallel-axis theorem about the common COM)."""
    mass = sum(part.mass for part in parts)
    com = sum(part.mass * part.position for part in parts) / mass
    inertia = np.zeros((3, 3))
    for part in parts:
        d = part.position - com
        inertia += part.inertia + part.mass * (d @ d * np.eye(3) - np.outer(d, d))
    return LinkInertial(mass=mass, com=com, inertia=inertia)


def plate_extent(index: int) -> tuple[float, float]:
    """Returns the (top, bottom) y coordinates of link ``index``'s plate in its frame."""
    top = PLATE_END_MARGIN
    if index < 2:
        return top, -(LINK_LENGTHS[index] + PLATE_END_MARGIN)
    return top, -fingertip_center_distance()


def plate_size(index: int) -> tuple[float, float, float]:
    """Returns the (x, y, z) edge lengths of link ``index``'s plate, m."""
    top, bottom = plate_extent(index)
    return PLATE_WIDTH, top - bottom, PLATE_THICKNESS


def plate_center(index: int) -> np.ndarray:
    """Returns the centre of link ``index``'s plate in the link frame, m."""
    top, bottom = plate_extent(index)
    return np.array([0.0, 0.5 * (top + bottom), 0.0])


def fingertip_center_distance() -> float:
    """Returns the distance from joint 3 to the fingertip sphere's centre, m."""
    return LINK_LENGTHS[2] - FINGERTIP_RADIUS


def drive_mass() -> float:
    """Returns the mass of one drive unit (motor + gearhead), kg."""
    return MOTOR_MASS + GEARHEAD_MASS


def drive_part(name: str, position: np.ndarray) -> Part:
    """Returns a drive unit centred at ``position`` with its axis along z."""
    mass = drive_mass()
    return Part(name, mass, position, cylinder_inertia(mass, DRIVE_RADIUS, DRIVE_LENGTH))


def link_parts() -> dict[str, list[Part]]:
    """Returns the components of every body, positions in that body's frame."""
    parts: dict[str, list[Part]] = {}
    block_mass = ALUMINIUM_DENSITY * math.prod(BASE_BLOCK_SIZE)
    block_center = np.array([0.0, 0.0, -(0.5 * DRIVE_LENGTH + 0.5 * BASE_BLOCK_SIZE[2])])
    parts["base"] = [
        Part("base block", block_mass, block_center, box_inertia(block_mass, BASE_BLOCK_SIZE)),
        drive_part("joint1 drive", np.zeros(3)),
    ]
    for index, link in enumerate(LINK_NAMES):
        size = plate_size(index)
        mass = ALUMINIUM_DENSITY * math.prod(size)
        parts[link] = [Part(f"{link} plate", mass, plate_center(index), box_inertia(mass, size))]
    parts["link1"].append(drive_part("joint2 drive", np.array([0.0, -LINK_LENGTHS[0], 0.0])))
    parts["link2"].append(drive_part("joint3 drive", np.array([0.0, -LINK_LENGTHS[1], 0.0])))
    tip_center = np.array([0.0, -fingertip_center_distance(), 0.0])
    parts["link3"].append(
        Part(
            "fingertip",
            FINGERTIP_MASS,
            tip_center,
            sphere_inertia(FINGERTIP_MASS, FINGERTIP_RADIUS),
        )
    )
    return parts


def link_inertials() -> dict[str, LinkInertial]:
    """Returns mass, COM and inertia about the COM of base, link1, link2 and link3."""
    return {name: combine(parts) for name, parts in link_parts().items()}


def inertia_about_joint(link: str) -> float:
    """Returns a link's moment of inertia about its own joint axis (z through origin)."""
    inertial = link_inertials()[link]
    return float(inertial.inertia[2, 2] + inertial.mass * (inertial.com[:2] @ inertial.com[:2]))


def forward_kinematics(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Returns absolute link angles and the points (joint 1, joint 2, joint 3, tip), eq. 18."""
    angles = np.cumsum(q)
    points = np.zeros((4, 2))
    for i, (length, angle) in enumerate(zip(LINK_LENGTHS, angles, strict=True)):
        points[i + 1] = points[i] + length * np.array([math.sin(angle), -math.cos(angle)])
    return angles, points


def inverse_kinematics(x: float, y: float, theta: float, elbow: int) -> np.ndarray:
    """Returns q reaching tip (x, y) with angle theta; elbow = +1 or -1 picks sign(q2)."""
    l1, l2, l3 = LINK_LENGTHS
    wx, wy = x - l3 * math.sin(theta), y + l3 * math.cos(theta)
    cos_q2 = (wx**2 + wy**2 - l1**2 - l2**2) / (2.0 * l1 * l2)
    if abs(cos_q2) > 1.0:
        raise ValueError(f"tip ({x}, {y}, {theta}) is out of reach")
    q2 = elbow * math.acos(cos_q2)
    q1 = math.atan2(wx, -wy) - math.atan2(l2 * math.sin(q2), l1 + l2 * math.cos(q2))
    return np.array([q1, q2, theta - q1 - q2])


def holding_torques(q: np.ndarray, wall_force: float) -> np.ndarray:
    """Returns the joint torques that hold the arm still against gravity (along -y) while
    the fingertip presses the wall with ``wall_force`` along +x (the wall pushes back)."""
    angles, points = forward_kinematics(q)
    inertials = link_inertials()
    com_x = [
        points[i, 0] - inertials[link].com[1] * math.sin(angles[i])
        for i, link in enumerate(LINK_NAMES)
    ]
    torques = np.zeros(3)
    for j in range(3):
        gravity = sum(
            inertials[LINK_NAMES[i]].mass * GRAVITY * (com_x[i] - points[j, 0]) for i in range(j, 3)
        )
        torques[j] = gravity + wall_force * (points[j, 1] - points[3, 1])
    return torques


def task_configurations() -> list[np.ndarray]:
    """Returns IK solutions (both elbows) on a grid over the task region, theta = pi/2."""
    configurations = []
    for x in np.linspace(*TASK_X_RANGE, TASK_GRID):
        for y in np.linspace(*TASK_Y_RANGE, TASK_GRID):
            for elbow in (1, -1):
                configurations.append(inverse_kinematics(x, y, TASK_THETA, elbow))
    return configurations


def required_torques(wall_force: float = SENSOR_FULL_SCALE) -> np.ndarray:
    """Returns max |holding torque| per joint over the task region and both elbows, N m."""
    return np.max([np.abs(holding_torques(q, wall_force)) for q in task_configurations()], axis=0)


def effort_limits() -> np.ndarray:
    """Returns the effort limits: full-scale requirement rounded up to EFFORT_STEP, N m."""
    return EFFORT_STEP * np.ceil(required_torques() / EFFORT_STEP)


def gear_ratios() -> np.ndarray:
    """Returns the smallest integer ratios at which the motor's stall torque, through the
    gearhead, reaches each joint's effort limit."""
    return np.ceil(effort_limits() / (MOTOR_STALL_TORQUE * GEARHEAD_EFFICIENCY))


def velocity_limits() -> np.ndarray:
    """Returns the joint speed limits: motor no-load speed over the gear ratio, rad/s."""
    return MOTOR_NO_LOAD_SPEED / gear_ratios()


def rotor_inertias() -> np.ndarray:
    """Returns each actuator's rotor inertia (motor side), kg m^2."""
    return np.full(3, MOTOR_ROTOR_INERTIA)


def reflected_inertias() -> np.ndarray:
    """Returns rotor inertia times gear ratio squared, as Drake adds it to each joint."""
    return rotor_inertias() * gear_ratios() ** 2


def continuous_torques() -> np.ndarray:
    """Returns the continuous output torque of each drive, N m."""
    return MOTOR_CONTINUOUS_TORQUE * gear_ratios() * GEARHEAD_EFFICIENCY


def joint3_misalignment_tolerance() -> float:
    """Returns how far (rad) link 3 may turn off the wall normal while the full-scale force
    still stays within joint 3's effort limit (gravity included at the task points)."""
    gravity = required_torques(wall_force=0.0)[2]
    ratio = (effort_limits()[2] - gravity) / (SENSOR_FULL_SCALE * LINK_LENGTHS[2])
    return math.asin(min(1.0, ratio))


def _vector(values: np.ndarray) -> str:
    """Formats numbers with enough digits for a 1e-6 relative comparison."""
    return " ".join(f"{v:.12g}" for v in values)


def print_table() -> None:
    """Prints the derived parameters as a table."""
    inertials = link_inertials()
    print("Bodies (link frame at its joint; inertia about the COM, link axes)")
    print(
        f"{'body':<7}{'mass kg':>10}{'com y m':>11}{'Ixx':>12}{'Iyy':>12}{'Izz':>12}"
        f"{'Izz joint':>12}"
    )
    for name, inertial in inertials.items():
        diagonal = np.diag(inertial.inertia)
        about_joint = inertia_about_joint(name) if name != "base" else float("nan")
        print(
            f"{name:<7}{inertial.mass:>10.4f}{inertial.com[1]:>11.5f}"
            f"{diagonal[0]:>12.4e}{diagonal[1]:>12.4e}{diagonal[2]:>12.4e}"
            f"{about_joint:>12.4e}"
        )
    print("\nComponents")
    for body, parts in link_parts().items():
        for part in parts:
            print(
                f"  {body:<6} {part.name:<14} {part.mass:8.4f} kg at y = {part.position[1]:+.5f}"
                f" m, z = {part.position[2]:+.4f} m"
            )
    print(f"\nDrive: {MOTOR_PART} + {GEARHEAD_PART}, {drive_mass():.3f} kg per unit")
    full_scale, paper_task = required_torques(), required_torques(PAPER_FORCE_REFERENCE)
    rows = [
        ("required, 100 N + gravity (N m)", full_scale),
        ("required, 5 N + gravity (N m)", paper_task),
        ("effort limit (N m)", effort_limits()),
        ("gear ratio", gear_ratios()),
        ("continuous output torque (N m)", continuous_torques()),
        ("velocity limit (rad/s)", velocity_limits()),
        ("rotor inertia (kg m^2)", rotor_inertias()),
        ("reflected inertia N^2 Jr (kg m^2)", reflected_inertias()),
    ]
    print(f"{'':<36}" + "".join(f"{name:>12}" for name in JOINT_NAMES))
    for label, values in rows:
        print(f"{label:<36}" + "".join(f"{v:>12.4g}" for v in values))
    print(
        f"\nJoint 3 holds the full-scale force up to "
        f"{math.degrees(joint3_misalignment_tolerance()):.1f} deg off the wall normal."
    )


def print_xml() -> None:
    """Prints the URDF elements that carry the derived numbers."""
    for name, inertial in link_inertials().items():
        i = inertial.inertia
        print(
            f'<!-- {name} -->\n<inertial>\n  <origin xyz="{_vector(inertial.com)}" rpy="0 0 0"/>'
            f'\n  <mass value="{inertial.mass:.12g}"/>\n  <inertia ixx="{i[0, 0]:.12g}" '
            f'ixy="{i[0, 1]:.12g}" ixz="{i[0, 2]:.12g}" iyy="{i[1, 1]:.12g}" '
            f'iyz="{i[1, 2]:.12g}" izz="{i[2, 2]:.12g}"/>\n</inertial>'
        )
    for name, effort, velocity, ratio, rotor in zip(
        JOINT_NAMES,
        effort_limits(),
        velocity_limits(),
        gear_ratios(),
        rotor_inertias(),
        strict=True,
    ):
        print(
            f'<!-- {name} -->\n<limit lower="-3.14159265359" upper="3.14159265359" '
            f'effort="{effort:.12g}" velocity="{velocity:.12g}"/>\n'
            f'<drake:rotor_inertia value="{rotor:.12g}"/>\n'
            f'<drake:gear_ratio value="{ratio:.12g}"/>'
        )


def main() -> None:
    """Prints the table, or the URDF snippets with --xml."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--xml", action="store_true", help="print URDF snippets")
    if parser.parse_args().xml:
        print_xml()
    else:
        print_table()


if __name__ == "__main__":
    main()
