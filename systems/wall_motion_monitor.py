"""A wall that approaches the arm, seen from the force rate and the tip's motion.

In contact the spring of eq. 4 gives F = Ke (x - Xe), so the wall's own speed toward the
tip, v_w = -dXe/dt, is

    v_w = F' / Ke - x'.

On a static wall the force rises only while the tip advances (F' = Ke x'), and on a
receding one only while the tip advances faster than the wall: a force that rises while the
tip does not advance (F' > 0, x' <= 0) is a wall that approaches. With an estimate that is
not below the wall (k_hat >= Ke, the estimator's cautious side), F' / k_hat <= F' / Ke for
F' >= 0, so

    v_hat = F' / k_hat - x'

is a lower bound on v_w: the monitor does not see a wall faster than it is. Sampled with the
sensor (period T): F' is the trusted reading's difference quotient over the last sample,
x' the tip's speed along the normal at the sample. The evidence needs the force to rise by
more than the reading's noise over the sample, 3 sqrt(2) sigma (a chance of 0.13 % per
sample for Gaussian noise), and the tip not to advance; without it the output is 0. Once
there is evidence it holds while the tip is pushed back (x' < 0), with v_hat computed as
above whatever the sign of F': a wall that keeps approaching at the speed the tip already
retreats at no longer raises the force, and must not lose its evidence for it. On a
static wall a tip that retreats at x' lowers the force at Ke x', so the held v_hat is
abs(x') (1 - Ke / k_hat): a retreat at v_hat shrinks by that factor each sample, and the
hold ends once v_hat is 0 or the law no longer acts on it (v_hat <= v_f).

The law (systems/safe_admittance.py) compares v_hat with the wall speed it can guarantee,
v_f = v_max (Fmax - Fr) / Fmax (docs/evidence/safety-beyond-bounds.md, section 7), and above it
moves the command
back at v_hat on top of its own rate.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import BasicVector_, LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from admittance.systems.contact_frame import ContactFrame

__all__ = ["WallMotionMonitor", "WallMotionMonitor_", "approach_evidence"]

# The force's rise over one sample must exceed this many deviations of the difference of
# two noisy readings (sqrt(2) sigma).
NOISE_DEVIATIONS = 3.0

# Discrete state layout: the last trusted reading in contact (NaN when there is none), the
# approach speed v_hat of the last sample.
_LAST_FORCE, _SPEED = 0, 1


def _value(x) -> float:
    return float(x) if isinstance(x, float | int) else float(x.value())


def approach_evidence(
    last_force: float,
    force: float,
    tip_speed: float,
    stiffness_estimate: float,
    *,
    period: float,
    noise_std: float,
    last_speed: float = 0.0,
) -> float:
    """v_hat = (F[k] - F[k-1]) / (T k_hat) - x' (module docstring), m/s, or 0 without
    evidence: no previous reading in contact (NaN), a tip that advances, or a rise within
    the noise, unless the last sample had evidence (`last_speed` > 0) and the tip is still
    pushed back (the hold: v_hat as above, whatever the force's sign of change)."""
    rise = force - last_force
    if not math.isfinite(rise) or tip_speed > 0.0:
        return 0.0
    held = last_speed > 0.0 and tip_speed < 0.0
    if rise <= NOISE_DEVIATIONS * math.sqrt(2.0) * noise_std and not held:
        return 0.0
    return max(rise / (period * stiffness_estimate) - tip_speed, 0.0)


class _WallMotionMonitor:
    """The approach speed of the wall in contact, sampled (module docstring).

    State (discrete, period T): [F[k-1] or NaN, v_hat]. Output: v_hat, m/s (>= 0).

    .. pydrake_system::

        name: WallMotionMonitor
        input_ports:
        - measured_force
        - estimated_state
        - stiffness_estimate
        - sensor_fault
        output_ports:
        - wall_approach_speed
    """

    def _construct(
        self,
        plant,
        *,
        contact: ContactFrame,
        period: float,
        noise_std: float,
        contact_force: float,
        converter=None,
    ) -> None:
        """
        Args:
            plant: finalized MultibodyPlant_[T] of the arm.
            contact: the contact frame, its task vector X and the normal's index in X.
            period: T, the sample period (the sensor's), s.
            noise_std: sigma, the reading's noise, N (>= 0).
            contact_force: F_c, the threshold of contact, N.
        """
        T = self._T
        LeafSystem_[T].__init__(self, converter=converter)
        for name, value, least in (
            ("period", period, 0.0),
            ("contact_force", contact_force, 0.0),
        ):
            if not (math.isfinite(value) and value > least):
                raise ValueError(f"{name} must be > 0, got {value}")
        if not (math.isfinite(noise_std) and noise_std >= 0.0):
            raise ValueError(f"noise_std must be >= 0, got {noise_std}")
        self._plant = plant
        self._arguments = dict(
            contact=contact,
            period=float(period),
            noise_std=float(noise_std),
            contact_force=float(contact_force),
        )
        self._period = float(period)
        self._noise = float(noise_std)
        self._contact_force = float(contact_force)
        self._normal_axis = contact.normal_axis
        self._kinematics = contact.kinematics(plant)
        nq, nv = plant.num_positions(), plant.num_velocities()
        self._num_positions = nq
        self.measured_force_input = self.DeclareVectorInputPort("measured_force", 1)
        self.estimated_state_input = self.DeclareVectorInputPort("estimated_state", nq + nv)
        self.stiffness_estimate_input = self.DeclareVectorInputPort("stiffness_estimate", 1)
        self.sensor_fault_input = self.DeclareVectorInputPort("sensor_fault", 1)
        self._state_index = self.DeclareDiscreteState(BasicVector_[T]([math.nan, 0.0]))
        self.DeclarePeriodicDiscreteUpdateEvent(
            period_sec=self._period, offset_sec=0.0, update=self._Update
        )
        self.wall_approach_speed_output = self.DeclareVectorOutputPort(
            "wall_approach_speed",
            1,
            lambda context, output: output.SetFromVector(
                [context.get_discrete_state(self._state_index)[_SPEED]]
            ),
            prerequisites_of_calc={self.xd_ticket()},
        )

    def _construct_copy(self, other, converter=None) -> None:
        _WallMotionMonitor._construct(
            self, other._plant.ToScalarType[self._T](), converter=converter, **other._arguments
        )

    def _Update(self, context, discrete_state) -> None:
        T = self._T
        last = _value(context.get_discrete_state(self._state_index)[_LAST_FORCE])
        last_speed = _value(context.get_discrete_state(self._state_index)[_SPEED])
        force = _value(self.measured_force_input.Eval(context)[0])
        trusted = _value(self.sensor_fault_input.Eval(context)[0]) < 0.5
        if not (trusted and math.isfinite(force) and force >= self._contact_force):
            new = [math.nan, 0.0]
        else:
            state = self.estimated_state_input.Eval(context)
            self._kinematics.set_state(
                state if T is float else np.array([T(_value(x)) for x in state])
            )
            row = [_value(j) for j in self._kinematics.jacobian()[self._normal_axis]]
            velocity = [_value(v) for v in state[self._num_positions :]]
            tip_speed = float(np.dot(row, velocity))
            estimate = _value(self.stiffness_estimate_input.Eval(context)[0])
            speed = approach_evidence(
                last,
                force,
                tip_speed,
                estimate,
                period=self._period,
                noise_std=self._noise,
                last_speed=last_speed,
            )
            new = [force, speed]
        discrete_state.get_mutable_vector(self._state_index).SetFromVector([T(x) for x in new])


@TemplateSystem.define("WallMotionMonitor_", T_list=[float, AutoDiffXd])
def WallMotionMonitor_(T):
    class Impl(_WallMotionMonitor, LeafSystem_[T]):
        __doc__ = _WallMotionMonitor.__doc__
        _T = T
        # TemplateSystem looks for them in the class itself.
        _construct = _WallMotionMonitor._construct
        _construct_copy = _WallMotionMonitor._construct_copy

    return Impl


WallMotionMonitor = WallMotionMonitor_[None]
