"""The spatial arm's gains checked against the sampled loop whose command comes late: the
hardware split's check at its start and while it runs (docs/evidence/hardware.md).

A controller that answers the robot's status at t_k has its command act from the robot's
next tick on: one period late when it answers within the period, N periods late when its
latency spans N - 1 more statuses. Its gains must keep two loops stable at that period h
and delay N:

* **the damper**: the 6-D PID's damping through the arm, h max eig(J M^-1 J^T Kd)
  (``systems.sampled_loop.damper_gain``), below the limit of a velocity mode damped from
  its value N periods old (``systems.sampled_loop.delayed_damper_limit``: 2 without delay,
  1 with one period, 0.618 with two). On the Panda the largest mode is the wrist's last
  joint, the rotation about the tool: kd_rz / M_77;
* **the force loop along the normal**: the reduced model of ``robots.spatial_arm.analysis``
  (``normal_map``: the apparent mass, the contact, the PID's z gains and the law, sampled
  at h with the PID's force held one period, the simulated loop's order), its command
  delayed N - 1 periods more by a shift register; its critical Gamma by the same
  bisection (``spatial_critical_gamma``).
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass

import numpy as np

from admittance.diagrams.analysis.linear import critical_gain
from admittance.diagrams.robots.spatial_arm.analysis import (
    NormalModel,
    normal_map,
    normal_model,
    state_names,
)
from admittance.diagrams.robots.spatial_arm.scenario import SpatialScenario
from admittance.systems.sampled_loop import damper_gain, delayed_damper_limit

__all__ = [
    "SampledGainCheck",
    "check_sampled_gains",
    "delayed_normal_map",
    "normal_model_at",
]

# The rotation about the tool (rz) and the names of the PID's six axes, for the messages.
AXES = ("x", "y", "z", "rx", "ry", "rz")


def normal_model_at(scenario: SpatialScenario, positions, period: float) -> NormalModel:
    """``robots.spatial_arm.analysis.normal_model`` of `scenario` with the arm at `positions`,
    sampled at `period`. A scenario with the wrist sensor is read with the ideal one (the
    reduced model has no sensor filter: its lag takes some of the margin), and one with
    the safety layer without it (the layer's bounds act only near them).

    Raises:
        ScenarioError: the controller is not the paper's law (one line).
    """
    if scenario.sensor.kind != "ideal" or scenario.safety.enabled:
        scenario = copy.deepcopy(scenario)
        scenario.sensor.kind = "ideal"
        scenario.safety.enabled = False
    model, _ = normal_model(scenario, positions)
    return dataclasses.replace(model, period=float(period))


def delayed_normal_map(model: NormalModel, delay: int) -> np.ndarray:
    """``normal_map`` with the PID's force acting `delay` periods after the state it was
    computed from (1: normal_map itself, the force held one period): the plant's rows
    (z, v) read the oldest of delay - 1 extra held forces instead of u."""
    A = normal_map(model)
    extra = int(delay) - 1
    if extra <= 0:
        return A
    names = state_names(model)
    force, plant_rows = names.index("u"), [names.index("z"), names.index("v")]
    size = A.shape[0]
    delayed = np.zeros((size + extra, size + extra))
    delayed[:size, :size] = A
    oldest = size + extra - 1
    for row in plant_rows:
        delayed[row, oldest] = A[row, force]
        delayed[row, force] = 0.0
    delayed[size, force] = 1.0
    for index in range(size + 1, size + extra):
        delayed[index, index - 1] = 1.0
    return delayed


@dataclass(frozen=True)
class SampledGainCheck:
    """What the check found at one period and delay."""

    # h: the command's period, s.
    period: float
    # N: periods from the state a command reads to the command acting.
    delay_periods: int
    # h max eig(J M^-1 J^T Kd) and its limit at N periods of delay.
    damper_gain: float
    damper_limit: float
    # The axis whose damping the largest mode is mostly (rz on the Panda: the wrist).
    damper_axis: str
    # The law's Gamma and the force loop's critical Gamma (None: stable up to 1e-2).
    gamma: float
    critical_gamma: float | None

    @property
    def damper_stable(self) -> bool:
        return self.damper_gain < self.damper_limit

    @property
    def force_loop_stable(self) -> bool:
        return self.critical_gamma is None or self.gamma < self.critical_gamma

    @property
    def stable(self) -> bool:
        return self.damper_stable and self.force_loop_stable

    @property
    def rate_needed(self) -> float:
        """The lowest rate at which the damper is stable at this delay (0: no damper), Hz."""
        return self.damper_gain / (self.period * self.damper_limit)

    def problem(self) -> str | None:
        """One line naming the keys and the fix, or None when the gains are within bounds."""
        late = f"{self.delay_periods} period(s) late"
        where = f"at {1.0 / self.period:.4g} Hz with the command {late}"
        parts = []
        if not self.damper_stable:
            parts.append(
                f"pid.kd, rate: the PID's damping is unstable {where}: h max eig(J M^-1 J^T Kd) "
                f"= {self.damper_gain:.3g} ({self.damper_axis} mostly), must be below "
                f"{self.damper_limit:.3g}; lower pid.kd ({self.damper_axis}) or run above "
                f"{self.rate_needed:.4g} Hz"
            )
        if not self.force_loop_stable:
            parts.append(
                f"admittance.gamma: {self.gamma:.3g} is above the sampled force loop's "
                f"critical Gamma {self.critical_gamma:.3g} {where}; lower admittance.gamma"
            )
        return "; ".join(parts) or None

    def as_dict(self) -> dict:
        return {
            "period": self.period,
            "rate": 1.0 / self.period,
            "delay_periods": self.delay_periods,
            "damper_gain": self.damper_gain,
            "damper_limit": self.damper_limit,
            "damper_axis": self.damper_axis,
            "gamma": self.gamma,
            "critical_gamma": self.critical_gamma,
            "verdict": "stable" if self.stable else "unstable",
        }


def _largest_mode_axis(jacobian, mass_matrix, kd) -> str:
    mobility = jacobian @ np.linalg.solve(mass_matrix, jacobian.T)
    values, vectors = np.linalg.eig(mobility @ np.diag(kd))
    mode = np.abs(vectors[:, int(np.argmax(values.real))].real)
    return AXES[int(np.argmax(mode))]


def check_sampled_gains(
    scenario: SpatialScenario,
    plant,
    plant_context,
    jacobian,
    *,
    period: float,
    delay: int = 1,
    gamma: float | None = None,
    model: NormalModel | None = None,
    kd=None,
    force_loop: bool = True,
) -> SampledGainCheck:
    """The scenario's PID and law checked at `period` with the command `delay` periods
    late, the arm at the state of `plant_context` (`jacobian`: the tool tip's 6 x n
    Jacobian in the control frame there). `gamma` overrides the scenario's; `model` (a
    NormalModel at another period) saves building the scenario's loop again; `kd` (6
    values) overrides pid.kd in the damper's check; without `force_loop` (a law other than
    the paper's) only the damper is checked (critical_gamma None)."""
    mass_matrix = plant.CalcMassMatrix(plant_context)
    jacobian = np.asarray(jacobian, dtype=float)
    kd = np.asarray(scenario.pid.kd if kd is None else kd, dtype=float)
    critical = None
    if force_loop and model is None:
        model = normal_model_at(scenario, plant.GetPositions(plant_context), period)
    if force_loop:
        critical = _critical_gamma(dataclasses.replace(model, period=float(period)), delay)
    return SampledGainCheck(
        period=float(period),
        delay_periods=int(delay),
        damper_gain=damper_gain(jacobian, mass_matrix, kd, period),
        damper_limit=delayed_damper_limit(int(delay)),
        damper_axis=_largest_mode_axis(jacobian, mass_matrix, kd),
        gamma=float(scenario.admittance.gamma if gamma is None else gamma),
        critical_gamma=critical,
    )


def _critical_gamma(model: NormalModel, delay: int) -> float | None:
    """The force loop's critical Gamma at `delay` periods (0.0: unstable at any)."""
    try:
        return critical_gain(
            lambda value: delayed_normal_map(model.with_gamma(value), delay),
            1e-9,
            1e-2,
            period=model.period,
        )
    except ValueError:  # the sampled PD on the contact is unstable at any Gamma
        return 0.0
