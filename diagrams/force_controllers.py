"""The force controller in front of the PID, chosen by ``controller.kind``, and its tuning.

Every kind has the ports of the paper's admittance block (``measured_force`` and
``desired_force`` in, ``reference_offset`` out; systems/force_axes.py), so the rest of the
loop (Fig. 1) is the same for all of them.

Fair tuning ("matched", the default). On a wall much stiffer than the arm, the arm's PID
acts on the force loop as a spring Kp, and the paper's law, Xr = Gamma K (z + alpha E) with
K = Kp, closes it with the crossover

    w_c = Kp Gamma K                (62.5 rad/s in paper_stiffness_step)

through its integral path. The baselines are given the same crossover:

* classical_admittance: D = 1 / (Gamma K), the same integral gain; M = D^2 / (4 Kp), which
  makes the force loop M s^2 + D s + Kp critically damped (its lag at w_c costs 14 deg).
* adaptive_impedance: the same m and b, and the adaptive term's zero an octave and more
  below the crossover, eta / lambda = w_c / 5 (65 deg of phase margin in the same model).
* fixed_reference: no gain; its estimates are the scenario's initial wall position plus
  ``controller.wall_position_error`` and initial stiffness times (1 + stiffness_error).

With ``controller.tuning: manual`` the baselines take controller.mass, .damping,
.stiffness and .adaptation_rate as given.
"""

from __future__ import annotations

from pydrake.systems.framework import DiagramBuilder

from admittance.diagrams.scenario import Scenario
from admittance.systems.adaptive_impedance import AdaptiveImpedance
from admittance.systems.classical_admittance import ClassicalAdmittance
from admittance.systems.fixed_reference import FixedReference
from admittance.systems.optimal_admittance import OptimalAdmittance

__all__ = ["AddForceController", "baseline_gains"]

# The wall-normal axis of X = (x, y, theta), the only force-controlled axis in the paper.
WALL_NORMAL_AXIS = 0


def baseline_gains(scenario: Scenario) -> dict[str, float]:
    """The gains the baselines run with (matched to the paper's law, or manual)."""
    controller = scenario.controller
    if controller.tuning == "manual":
        return {
            "mass": controller.mass,
            "damping": controller.damping,
            "stiffness": controller.stiffness,
            "adaptation_rate": controller.adaptation_rate,
        }
    kp = scenario.pid.kp[WALL_NORMAL_AXIS]
    integral_gain = scenario.admittance.gamma * kp  # Gamma K, m/(N s)
    crossover = kp * integral_gain  # rad/s
    damping = 1.0 / integral_gain
    return {
        "mass": damping**2 / (4.0 * kp),
        "damping": damping,
        "stiffness": 0.0,
        "adaptation_rate": crossover / 5.0,
    }


def AddForceController(builder: DiagramBuilder, scenario: Scenario):
    """Adds the force controller of `scenario.controller_kind`, named after its kind.

    Returns:
        the system, or None for pid_only (the PID then runs on Xd alone).
    """
    kind = scenario.controller_kind
    if kind == "pid_only":
        return None
    axes = [WALL_NORMAL_AXIS]
    gains = baseline_gains(scenario)
    if kind == "optimal_admittance":
        admittance = scenario.admittance
        system = OptimalAdmittance(
            gamma=admittance.gamma,
            alpha=admittance.alpha,
            # K of eq. 10 is the PID's stiffness on the wall-normal axis
            # (docs/paper-notes.md, section 4).
            stiffness=scenario.pid.kp[WALL_NORMAL_AXIS],
            force_axes=axes,
            num_axes=3,
            period=admittance.period,
            max_push=admittance.max_push,
            max_retract=admittance.max_retract,
            max_force=admittance.max_force,
            force_bound_gain=admittance.force_bound_gain,
        )
    elif kind == "fixed_reference":
        wall = scenario.wall
        system = FixedReference(
            wall_position=wall.position + scenario.controller.wall_position_error,
            wall_stiffness=wall.stiffness * (1.0 + scenario.controller.stiffness_error),
            force_axes=axes,
            num_axes=3,
        )
    elif kind == "classical_admittance":
        system = ClassicalAdmittance(
            mass=gains["mass"],
            damping=gains["damping"],
            stiffness=gains["stiffness"],
            force_axes=axes,
            num_axes=3,
        )
    elif kind == "adaptive_impedance":
        system = AdaptiveImpedance(
            mass=gains["mass"],
            damping=gains["damping"],
            adaptation_rate=gains["adaptation_rate"],
            force_axes=axes,
            num_axes=3,
        )
    else:  # validate() admits only CONTROLLER_KINDS
        raise ValueError(f"controller.kind: unknown kind {kind!r}")
    builder.AddSystem(system)
    system.set_name(kind)
    return system
