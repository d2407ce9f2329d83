"""The stability analysis of the safety layer: its map over Ke against the paper's law's,
confirmed by nonlinear simulation at the map's edges.

With the layer on, the Gamma of the map is the user's: the layer runs with
Gamma_s = min(Gamma, Gamma*(k_hat) / margin), the estimate frozen at the equilibrium's
(docs/safety.md). Each edge run starts at the contact equilibrium of the nonlinear diagram
(arm, PID, wall, sensor filter, the layer) and steps Fr by 0.5 N
(stability.simulate_near_critical): it is stable when contact holds and the force error's
peak over the last fifth of the run is below its peak over the first fifth.
"""

from __future__ import annotations

import itertools

import numpy as np

from admittance.diagrams.analysis.stability import simulate_near_critical, with_values
from admittance.diagrams.scenario.planar_arm import Scenario

__all__ = ["edge_confirmations", "unstable_points"]


def unstable_points(grid: np.ndarray) -> int:
    """How many points of a stability map have max Re(eig) >= 0 (NaN: no equilibrium)."""
    return int(np.sum(np.nan_to_num(grid, nan=-1.0) >= 0))


def edge_confirmations(
    scenario: Scenario, stiffness: tuple[float, float], gamma: tuple[float, float]
) -> list[dict]:
    """Nonlinear runs at the corners (Ke, Gamma) of a map, with the scenario's layer."""
    runs = []
    for ke, g in itertools.product(stiffness, gamma):
        run = simulate_near_critical(with_values(scenario, {"wall.stiffness": float(ke)}), g)
        run["stiffness"] = float(ke)
        run["stable"] = bool(
            run["contact_lost_time"] is None
            and run["peak_error_last_fifth"] < run["peak_error_first_fifth"]
        )
        runs.append(run)
    return runs
