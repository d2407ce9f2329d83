"""`admittance stability`: the stability report of one scenario (JSON, text and figures)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from admittance.diagrams.analysis.eq13 import symbolic_eq13
from admittance.diagrams.analysis.linear import lyapunov_certificate, modal_summary
from admittance.diagrams.results.folder import ResultFolder, result_folder
from admittance.diagrams.robots.planar_arm.linearization import (
    FindContactEquilibrium,
    LinearizeAtEquilibrium,
)
from admittance.diagrams.robots.planar_arm.run import run_scenario
from admittance.diagrams.robots.planar_arm.safety_margins import (
    continuous_counterpart,
    edge_confirmations,
    is_sampled,
    resolving_step,
    sampled_margins,
    sampled_stability_map,
    unstable_points,
)
from admittance.diagrams.robots.planar_arm.scenario import Scenario
from admittance.diagrams.robots.planar_arm.stability import (
    critical_gamma,
    linear_versus_nonlinear,
    lyapunov_along_trajectory,
    simulate_near_critical,
    stability_map,
    with_values,
)
from admittance.diagrams.robots.record import StabilityOptions
from admittance.diagrams.views.formatting import number

__all__ = [
    "MapAxes",
    "StabilityReport",
    "analyse",
    "arm_stability",
    "format_report",
    "write_report",
]


@dataclass
class MapAxes:
    """The grids of the stability maps (Gamma on every map's x axis)."""

    gamma: np.ndarray = field(default_factory=lambda: np.logspace(-7, -3, 17))
    stiffness: np.ndarray = field(default_factory=lambda: np.logspace(3, 7, 13))
    alpha: np.ndarray = field(default_factory=lambda: np.array([0, 0.01, 0.03, 0.1, 0.3, 1.0]))
    filter_cutoff: np.ndarray = field(default_factory=lambda: np.logspace(2, 4.5, 11))
    period: np.ndarray = field(default_factory=lambda: np.logspace(-5, -2, 10))

    @classmethod
    def quick(cls) -> MapAxes:
        """Coarse grids for tests and notebooks."""
        return cls(
            gamma=np.logspace(-7, -3, 5),
            stiffness=np.logspace(3, 7, 3),
            alpha=np.array([0.0, 0.1, 1.0]),
            filter_cutoff=np.array([1e2, 1e3, 1e4]),
            period=np.array([1e-4, 1e-3, 1e-2]),
        )


MAPS = {
    # name: (y key, MapAxes field, y label, overrides for the map)
    "gamma_vs_stiffness": ("wall.stiffness", "stiffness", "Ke (N/m)", {}),
    "gamma_vs_alpha": ("admittance.alpha", "alpha", "alpha (s)", {}),
    "gamma_vs_filter_cutoff": (
        "sensor.filter_cutoff",
        "filter_cutoff",
        "sensor filter cut-off (Hz)",
        {"sensor.kind": "flexiforce"},
    ),
    "gamma_vs_period": ("admittance.period", "period", "admittance period (s)", {}),
    # With safety.enabled, the paper's law on the same grid, for comparison.
    "gamma_vs_stiffness_without_safety": (
        "wall.stiffness",
        "stiffness",
        "Ke (N/m), safety layer off",
        {"safety.enabled": False},
    ),
    # A sampled controller: the reduced loop in one tick with the latency (sampled_margins).
    "gamma_vs_stiffness_sampled": (
        "wall.stiffness",
        "stiffness",
        "Ke (N/m), sampled loop with its latency (reduced model)",
        {},
    ),
}
SAMPLED_MAP = "gamma_vs_stiffness_sampled"


def _maps_of(scenario: Scenario) -> dict:
    """The maps that apply: the comparison only with the layer on, the sampled block's
    period only without it (the layer runs continuous)."""
    skip = "gamma_vs_period" if scenario.safety.enabled else "gamma_vs_stiffness_without_safety"
    return {name: spec for name, spec in MAPS.items() if name not in (skip, SAMPLED_MAP)}


@dataclass
class StabilityReport:
    scenario: Scenario
    summary: dict
    maps: dict[str, np.ndarray]
    axes: MapAxes
    trajectory: dict | None
    step: object


def _silent(stage: str) -> None:
    pass


def analyse(
    scenario: Scenario,
    *,
    axes: MapAxes | None = None,
    with_trajectory: bool = True,
    progress: Callable[[str], None] = _silent,
) -> StabilityReport:
    """Everything `admittance stability` reports for `scenario`.

    Args:
        progress: called with a short description as each stage starts.
    """
    axes = axes or MapAxes()
    summary: dict = {"scenario": scenario.name}
    run_scenario_as_given = scenario
    if is_sampled(scenario):
        # The loop that runs is sampled: its margins from the discrete-time reduced model;
        # Linearize reads the continuous loop under it (same gains, no tick, no latency).
        progress("the sampled loop with its latency: critical Gamma and tolerable latency")
        summary["sampled"] = sampled_margins(scenario)
        scenario = continuous_counterpart(scenario)
    _linearize(scenario, summary, progress)
    step = _step_comparison(scenario, summary, progress)
    _critical(scenario, summary, progress)
    maps = _maps(scenario, run_scenario_as_given, "sampled" in summary, axes, progress)
    if scenario.safety.enabled:
        summary["safety"] = _safety_layer(scenario, maps, axes, progress)
    trajectory = None
    if with_trajectory:
        trajectory = _trajectory(run_scenario_as_given, summary, progress)
    return StabilityReport(run_scenario_as_given, summary, maps, axes, trajectory, step)


def _linearize(scenario: Scenario, summary: dict, progress: Callable[[str], None]) -> None:
    """Eq. 13, the contact equilibrium and the linearized loop's modes and certificate."""
    progress("eq. 13 symbolically; the contact equilibrium and the linearized loop")
    summary["eq13"] = symbolic_eq13()
    equilibrium = FindContactEquilibrium(scenario)
    A = LinearizeAtEquilibrium(equilibrium).A()
    summary["equilibrium_residual"] = equilibrium.residual
    summary["num_states"] = int(A.shape[0])
    summary["modes"] = modal_summary(A)
    summary["resolving_step"] = resolving_step(A)
    summary["resolving_step"]["max_step_used"] = scenario.simulator.max_step_size
    certificate = lyapunov_certificate(A)
    certificate.pop("P", None)
    summary["lyapunov"] = certificate


def _step_comparison(scenario: Scenario, summary: dict, progress: Callable[[str], None]):
    """A 0.1 N step of Fr, linear against nonlinear; returns the two responses."""
    progress("a 0.1 N step of Fr, linear against nonlinear")
    step = linear_versus_nonlinear(scenario, step=0.1)
    summary["linear_versus_nonlinear"] = {
        "step_N": 0.1,
        "max_difference_N": float(np.max(np.abs(step.linear - step.nonlinear))),
        "relative_to_step": float(np.max(np.abs(step.linear - step.nonlinear)) / 0.1),
    }
    return step


def _critical(scenario: Scenario, summary: dict, progress: Callable[[str], None]) -> None:
    """The critical Gamma, its margin, and a nonlinear run on either side of it."""
    progress("the critical Gamma, and a simulation on either side of it")
    gamma_critical = critical_gamma(scenario)
    summary["critical_gamma"] = gamma_critical
    summary["gamma"] = scenario.admittance.gamma
    if gamma_critical is not None:
        summary["gamma_margin"] = gamma_critical / scenario.admittance.gamma
        summary["confirmation"] = {
            "below": simulate_near_critical(scenario, 0.8 * gamma_critical),
            "above": simulate_near_critical(scenario, 1.25 * gamma_critical),
        }


def _maps(
    scenario: Scenario,
    run_scenario_as_given: Scenario,
    sampled: bool,
    axes: MapAxes,
    progress: Callable[[str], None],
) -> dict[str, np.ndarray]:
    """The stability maps that apply (and the sampled loop's, for a sampled controller)."""
    maps = {}
    applicable = _maps_of(scenario)
    for index, (name, (key, axis, _, overrides)) in enumerate(applicable.items(), start=1):
        size = len(axes.gamma) * len(getattr(axes, axis))
        progress(f"stability map {index} of {len(applicable)}: {name} ({size} linearizations)")
        base = with_values(scenario, overrides) if overrides else scenario
        maps[name] = stability_map(base, "admittance.gamma", axes.gamma, key, getattr(axes, axis))
    if sampled:
        maps[SAMPLED_MAP] = sampled_stability_map(run_scenario_as_given, axes.gamma, axes.stiffness)
    return maps


def _safety_layer(
    scenario: Scenario, maps: dict, axes: MapAxes, progress: Callable[[str], None]
) -> dict:
    """The safety layer's map against the paper's law's, and nonlinear runs at its corners."""
    progress("the safety layer: nonlinear runs at the corners of its map over Ke")
    edges = (float(axes.stiffness[0]), float(axes.stiffness[-1]))
    return {
        "unstable_points_with_layer": unstable_points(maps["gamma_vs_stiffness"]),
        "unstable_points_without_layer": unstable_points(maps["gamma_vs_stiffness_without_safety"]),
        "map_points": int(maps["gamma_vs_stiffness"].size),
        "edges": edge_confirmations(scenario, edges, (float(axes.gamma[0]), float(axes.gamma[-1]))),
    }


def _trajectory(scenario: Scenario, summary: dict, progress: Callable[[str], None]) -> dict:
    """V(t) along a simulated run of the scenario as given."""
    progress(f"V(t) along a simulated run of {number(scenario.duration, ' s')}")
    result = run_scenario(scenario)
    trajectory = lyapunov_along_trajectory(result)
    summary["lyapunov_along_trajectory"] = {
        "monotone_after_contact": trajectory["monotone_after_contact"],
        "growing_fraction": trajectory["growing_fraction"],
        "growing_intervals": trajectory["growing_intervals"][:50],
        "growing_intervals_total": len(trajectory["growing_intervals"]),
    }
    return trajectory


def _latency_text(latency) -> str:
    return "> 100 ms" if latency is None else number(1e3 * latency, " ms", digits=3)


def _sampled_lines(sampled: dict) -> list[str]:
    """The sampled loop's margins (safety_margins.sampled_margins) as report lines."""
    lines = [
        f"The loop that runs: PID and law in one tick of {number(1e3 * sampled['period'])} ms, "
        f"the reading {number(1e3 * sampled['latency'])} ms late (reduced model: m = "
        f"{number(sampled['apparent_mass'], ' kg', digits=4)}, Kd + c = "
        f"{number(sampled['damping'], ' N s/m', digits=4)}):",
        f"  on the wall (Ke {number(sampled['stiffness'], ' N/m')}): critical Gamma "
        f"{number(sampled['critical_gamma'], digits=4)} with the latency, "
        f"{number(sampled['critical_gamma_without_latency'], digits=4)} without it, "
        f"{number(sampled['critical_gamma_continuous'], digits=4)} for the continuous loop",
        f"  scheduled Gamma {number(sampled['scheduled_gamma'], digits=4)} (the scenario's "
        f"{number(sampled['gamma'])}); spectral radius there "
        f"{number(sampled['spectral_radius'], digits=5)}; tolerable latency at the scheduled "
        f"gains {_latency_text(sampled['tolerable_latency'])}",
        "  Ke (N/m)   critical Gamma   scheduled Gamma   tolerable latency",
    ]
    for row in sampled["table"]:
        lines.append(
            f"  {row['stiffness']:8.0e}   {row['critical_gamma']:14.4g}   "
            f"{row['scheduled_gamma']:15.4g}   {_latency_text(row['tolerable_latency'])}"
        )
    return lines + [
        "Below: the continuous loop under it (Linearize needs it; no tick, no latency).",
        "",
    ]


def format_report(summary: dict) -> str:
    """report.txt: eq. 13, the linearized loop, the critical Gamma, the safety layer and
    V(t) along the run (each where the summary has it)."""
    lines = [
        f"Stability of scenario {summary['scenario']}",
        "",
        *(_sampled_lines(summary["sampled"]) if "sampled" in summary else []),
        *_eq13_lines(summary["eq13"]),
        *_linear_lines(summary),
        *_critical_lines(summary),
    ]
    safety = summary.get("safety")
    if safety:
        lines += _safety_lines(safety)
    trajectory = summary.get("lyapunov_along_trajectory")
    if trajectory:
        lines.append(
            f"V = 1/2 (E + alpha dE/dt)^2 along the run: monotone after contact = "
            f"{trajectory['monotone_after_contact']}; grows on "
            f"{trajectory['growing_intervals_total']} intervals, "
            f"{number(100 * trajectory['growing_fraction'], ' %')} of the time"
        )
    return "\n".join(lines) + "\n"


def _eq13_lines(eq13: dict) -> list[str]:
    """Eq. 13 checked symbolically: the corrected law's dV/dt and the printed sign's."""
    return [
        "Eq. 13 (pydrake.symbolic, per axis):",
        f"  dI/dXr = -K (E + alpha dE/dt): {eq13['dI_dXr_equals_minus_K_weighted_error']}",
        "  corrected law dXr/dt = +Gamma K (E + alpha dE/dt) gives "
        f"dV/dt = -(E + alpha dE/dt)^2 K Gamma K: {eq13['corrected_identity']}",
        "  printed eq. 10 (minus sign) gives dV/dt = +(E + alpha dE/dt)^2 K Gamma K: "
        f"{eq13['printed_sign_grows']}",
        "",
    ]


def _linear_lines(summary: dict) -> list[str]:
    """The linearized loop: its modes, eigenvalues, Lyapunov certificate, the step that
    resolves its fastest mode, and the linear against the nonlinear step response."""
    modes = summary["modes"]
    lyapunov = summary["lyapunov"]
    lines = [
        f"Linearized closed loop at the contact equilibrium ({summary['num_states']} states, "
        f"residual {number(summary['equilibrium_residual'], digits=2)}):",
        f"  stable: {modes['stable']} (max real part "
        f"{number(modes['max_real_part'], ' 1/s', digits=4)})",
        f"  slowest time constant {number(modes['slowest_time_constant'], ' s', digits=4)}, "
        f"fastest {number(modes['fastest_time_constant'], ' s')}, least damping ratio "
        f"{number(modes['least_damped_ratio'])}",
        "  eigenvalues (1/s):",
    ]
    for (real, imag), zeta in zip(modes["eigenvalues"], modes["damping_ratios"], strict=True):
        lines.append(f"    {real:14.6g} {imag:+14.6g} j   damping {number(zeta)}")
    if lyapunov.get("positive_definite"):
        lines.append(
            "Lyapunov: A^T P + P A = -I has P > 0 (min eigenvalue "
            f"{number(lyapunov['min_eigenvalue'])}, condition number "
            f"{number(lyapunov['condition_number'])})"
        )
    else:
        lines.append(f"Lyapunov: no positive definite P ({lyapunov.get('error', 'P not > 0')})")
    resolution = summary["resolving_step"]
    lines.append(
        f"Fastest oscillatory mode {number(resolution['fastest_mode_hz'], ' Hz', digits=4)}: "
        f"a nonlinear run shows it with a step of at most "
        f"{number(1e3 * resolution['step'], ' ms', digits=3)} (10 per period); the runs "
        f"below cap the step at {number(1e3 * resolution['max_step_used'], ' ms', digits=3)}"
        + ("" if resolution["max_step_used"] <= resolution["step"] else " and cannot show it")
    )
    comparison = summary["linear_versus_nonlinear"]
    lines.append(
        f"Linear vs nonlinear, Fr step of {comparison['step_N']} N: max difference "
        f"{number(comparison['max_difference_N'], ' N')} "
        f"({number(100 * comparison['relative_to_step'], ' %')} "
        "of the step)"
    )
    return lines


def _critical_lines(summary: dict) -> list[str]:
    """The critical Gamma and the nonlinear runs either side of it."""
    critical = summary["critical_gamma"]
    if critical is None:
        return ["Critical Gamma: none up to 1e-2 (the linearized loop stays stable)"]
    confirmation = summary["confirmation"]
    return [
        f"Critical Gamma {number(critical, digits=4)} ({number(summary['gamma_margin'])} x the "
        f"scenario's {number(summary['gamma'])}); nonlinear check: at 0.8 x converges = "
        f"{confirmation['below']['converges']}, at 1.25 x converges = "
        f"{confirmation['above']['converges']} (contact lost at "
        f"{confirmation['above']['contact_lost_time']} s)"
    ]


def _safety_lines(safety: dict) -> list[str]:
    """The safety layer's unstable points against the paper's law's, and its corner runs."""
    lines = [
        f"Safety layer: {safety['unstable_points_with_layer']} unstable points of "
        f"{safety['map_points']} on the map of Gamma against Ke with the layer, "
        f"{safety['unstable_points_without_layer']} without it; nonlinear runs at its "
        "corners (0.5 N step of Fr):"
    ]
    for run in safety["edges"]:
        lines.append(
            f"  Ke {number(run['stiffness'], ' N/m')}, Gamma {number(run['gamma'])}: "
            f"stable = {run['stable']} (peak error {number(run['peak_error_first_fifth'])}"
            f" -> {number(run['peak_error_last_fifth'])} N, contact lost at "
            f"{run['contact_lost_time']})"
        )
    return lines


def _map_figure(report: StabilityReport, name: str):
    key, axis, label, _ = MAPS[name]
    grid = report.maps[name]
    y = getattr(report.axes, axis)
    figure, ax = plt.subplots(figsize=(7, 5))
    y_plot = y if np.all(y > 0) else np.arange(len(y))
    mesh = ax.pcolormesh(
        report.axes.gamma,
        y_plot,
        np.sign(grid) * np.log10(1 + np.abs(grid) / 0.01),
        cmap="RdBu_r",
        vmin=-6,
        vmax=6,
        shading="nearest",
    )
    ax.contour(report.axes.gamma, y_plot, grid, levels=[0.0], colors="k")
    ax.set_xscale("log")
    if np.all(y > 0):
        ax.set_yscale("log")
    else:
        ax.set_yticks(np.arange(len(y)), [f"{v:g}" for v in y])
    ax.axvline(report.scenario.admittance.gamma, color="g", ls="--", label="scenario Gamma")
    ax.set_xlabel("Gamma")
    ax.set_ylabel(label)
    ax.set_title(f"{name}\nmax Re(eig): blue stable, red unstable, black boundary", fontsize=10)
    ax.legend(loc="lower left")
    figure.colorbar(mesh, label="sign(s) log10(1 + |s| / 0.01), s = max Re(eig) (1/s)")
    return figure


def _eigenvalue_figure(report: StabilityReport):
    eigenvalues = np.array(report.summary["modes"]["eigenvalues"])
    figure, ax = plt.subplots(figsize=(6, 4))
    ax.scatter(eigenvalues[:, 0], eigenvalues[:, 1], marker="x")
    ax.set_xscale("symlog", linthresh=1.0)
    ax.set_xlabel("Re (1/s)")
    ax.set_ylabel("Im (rad/s)")
    ax.set_title("closed-loop eigenvalues at the contact equilibrium")
    ax.grid(True, alpha=0.3)
    return figure


def _step_figure(report: StabilityReport):
    figure, ax = plt.subplots(figsize=(7, 4))
    ax.plot(report.step.time, report.step.nonlinear, label="nonlinear diagram")
    ax.plot(report.step.time, report.step.linear, "--", label="Linearize")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("contact force change (N)")
    ax.set_title("response to a 0.1 N step of Fr")
    ax.legend()
    ax.grid(True, alpha=0.3)
    return figure


def _lyapunov_figure(trajectory: dict):
    figure, ax = plt.subplots(figsize=(7, 4))
    ax.semilogy(trajectory["time"], trajectory["V"] + 1e-12)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("V = 1/2 (E + alpha dE/dt)^2 (N^2)")
    ax.set_title("the paper's Lyapunov function along the run")
    ax.grid(True, alpha=0.3)
    return figure


def write_report(
    report: StabilityReport, out_dir: str | Path, overwrite: bool = True
) -> ResultFolder:
    """Writes report.json, report.txt and the figures atomically; returns what it wrote."""
    data = dict(report.summary)
    data["maps"] = {
        name: {
            "gamma": report.axes.gamma.tolist(),
            MAPS[name][0]: getattr(report.axes, MAPS[name][1]).tolist(),
            "max_real_part": [[None if math.isnan(v) else v for v in row] for row in grid],
        }
        for name, grid in report.maps.items()
    }
    with result_folder(out_dir, overwrite=overwrite) as folder:
        folder.write_json("report.json", data)
        folder.write_text("report.txt", format_report(report.summary))
        for name in report.maps:
            folder.write_figure(f"map_{name}.png", _map_figure(report, name), dpi=100)
        folder.write_figure("eigenvalues.png", _eigenvalue_figure(report), dpi=100)
        folder.write_figure("step_linear_vs_nonlinear.png", _step_figure(report), dpi=100)
        if report.trajectory is not None:
            folder.write_figure(
                "lyapunov_along_trajectory.png", _lyapunov_figure(report.trajectory), dpi=100
            )
    return folder


def arm_stability(
    scenario: Scenario, out: Path, options: StabilityOptions, overwrite: bool, progress
) -> tuple[str, ResultFolder]:
    """`admittance stability` on the planar arm: the report written to `out`, and its text
    (quick: the coarse maps)."""
    axes = MapAxes.quick() if options.quick else MapAxes()
    report = analyse(scenario, axes=axes, with_trajectory=options.trajectory, progress=progress)
    progress(f"writing {out}/")
    folder = write_report(report, out, overwrite=overwrite)
    return format_report(report.summary), folder
