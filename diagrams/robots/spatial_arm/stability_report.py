"""`admittance stability` on a spatial-arm scenario: the whole loop and the reduced one.

The analysis is diagrams/robots/spatial_arm/analysis.py; this writes report.json, report.txt and
the eigenvalues against the unit circle through the result-folder writer.
"""

from __future__ import annotations

from pathlib import Path

from admittance.diagrams.results.folder import ResultFolder
from admittance.diagrams.robots.record import StabilityOptions
from admittance.diagrams.robots.spatial_arm.analysis import analyse_spatial_stability
from admittance.diagrams.robots.spatial_arm.scenario import SpatialScenario
from admittance.diagrams.views.formatting import number
from admittance.diagrams.views.sampled_report import write_sampled_report

__all__ = ["format_spatial_report", "spatial_stability", "write_spatial_report"]


def format_spatial_report(summary: dict) -> str:
    """report.txt: the model, its modes, the certificate and the critical Gamma."""
    lines = [
        f"Stability of spatial scenario {summary['scenario']}: the loop reduced to the normal, "
        f"sampled at h = {number(summary['period'], ' s')}, x = [{', '.join(summary['states'])}]",
        "",
        *_model_lines(summary),
        "",
        *_mode_lines(summary["modes"]),
        "",
        _lyapunov_line(summary["lyapunov"]),
        "",
        f"Critical Gamma (spectral radius reaches 1): {number(summary['critical_gamma'], digits=4)}"
        f" = {number(summary['margin'], digits=3)} x the scenario's; the continuous loop's "
        f"(Routh, h -> 0): {number(summary['continuous_critical_gamma'], digits=4)}; with the "
        "controllers reading the state after the plant's step (Drake's order in simulate): "
        f"{number(summary['after_step_critical_gamma'], digits=4)}",
    ]
    whole = summary.get("whole_loop")
    if whole is not None:
        lines += _whole_loop_lines(whole, summary["critical_gamma"])
        lines += ["", "The reduced model's critical Gamma, in runs from the scenario's start:"]
    lines += _confirmation_lines(summary.get("confirmation", []))
    return "\n".join(lines) + "\n"


def _model_lines(summary: dict) -> list[str]:
    """The contact equilibrium and the reduced model's parameters."""
    model, masses, equilibrium = summary["model"], summary["apparent_mass"], summary["equilibrium"]
    return [
        f"Contact equilibrium (the scenario's run at its end; at a lower Gamma if it does not "
        f"come to rest: the equilibrium does not depend on Gamma): F = "
        f"{number(equilibrium['force'], ' N', digits=4)} (Fr = "
        f"{number(equilibrium['force_reference'], ' N')})",
        f"  apparent mass along the normal: {number(masses['held'], ' kg', digits=3)} "
        f"(Lambda_zz, the other axes held; {number(masses['free'], ' kg', digits=3)} with them "
        "free)",
        f"  contact k = {number(model['contact_stiffness'], ' N/m')}, c = d Fr = "
        f"{number(model['contact_damping'], ' N s/m')}; PID z Kp = {number(model['kp'], ' N/m')}"
        f", Kd = {number(model['kd'], ' N s/m')}, Ki = {number(model['ki'])}; Gamma = "
        f"{number(model['gamma'], digits=3)}, alpha = {number(model['alpha'], ' s')}",
    ]


def _mode_lines(modes: dict) -> list[str]:
    """The map's eigenvalues, its spectral radius and slowest mode."""
    lines = [
        f"Eigenvalues of the map (spectral radius {number(modes['spectral_radius'], digits=5)}, "
        f"stable = {modes['stable']}):",
    ]
    for real, imag in modes["eigenvalues"]:
        lines.append(f"  {real:+.6f} {imag:+.6f} j   |z| = {abs(complex(real, imag)):.6f}")
    lines.append(
        f"  slowest time constant {number(modes.get('slowest_time_constant'), ' s', digits=3)}, "
        f"least damping ratio {number(modes.get('least_damped_ratio'), digits=3)}"
    )
    return lines


def _lyapunov_line(lyapunov: dict) -> str:
    """The discrete Lyapunov certificate, or why there is none."""
    return (
        "Lyapunov (A^T P A - P = -I, RealDiscreteLyapunovEquation): P > 0 = "
        f"{lyapunov['positive_definite']}"
        + (
            f", eigenvalues of P in [{number(lyapunov['min_eigenvalue'], digits=4)}, "
            f"{number(lyapunov['max_eigenvalue'], digits=4)}], residual "
            f"{number(lyapunov['residual'], digits=2)}"
            if "min_eigenvalue" in lyapunov
            else f" ({lyapunov.get('error')})"
        )
    )


def _whole_loop_lines(whole: dict, reduced_critical_gamma) -> list[str]:
    """The whole loop's step map: its spectral radius, certificate, critical Gamma and the
    nonlinear runs from rest either side of it."""
    certificate = whole["lyapunov"]
    lines = [
        "",
        f"The whole loop ({whole['states']} states: joints, contact, 6-D PID, law; one "
        "step differentiated through AutoDiffXd at the equilibrium; left out, feeding "
        f"nothing: {', '.join(whole['left_out']) or 'none'}):",
        f"  spectral radius {number(whole['spectral_radius'], digits=6)}, stable = "
        f"{whole['stable']}; P > 0 = {certificate['positive_definite']}"
        + (
            f" (condition number {number(certificate['condition_number'], digits=3)})"
            if certificate["positive_definite"]
            else ""
        ),
        f"  critical Gamma {number(whole['critical_gamma'], digits=4)} = "
        f"{number(whole['margin'], digits=3)} x the scenario's (the reduced model's is "
        f"{number(reduced_critical_gamma, digits=4)})",
    ]
    for run in whole.get("confirmation", []):
        verdict = "stable" if run["stable"] else "unstable"
        lines.append(
            f"  nonlinear run from rest at {run['factor']:g} x "
            f"({number(run['gamma'], digits=4)}), Xr stepped 0.1 mm: {verdict} (force "
            f"error {number(run['amplitude_first_quarter'], ' N', digits=3)} over its "
            f"first quarter, {number(run['amplitude_last_quarter'], ' N', digits=3)} "
            "over its last)"
        )
    return lines


def _confirmation_lines(confirmation: list) -> list[str]:
    """The reduced model's critical Gamma in nonlinear runs from the scenario's start."""
    lines = []
    for run in confirmation:
        verdict = "stable" if run["stable"] else "unstable"
        detail = (
            "diverged"
            if run["diverged"]
            else (
                f"force error amplitude {number(run['amplitude_second_to_last_s'], ' N', digits=3)}"
                f" then {number(run['amplitude_last_s'], ' N', digits=3)} over the last two "
                f"seconds, contact lost in the last second: {run['contact_lost_last_s']}"
            )
        )
        lines.append(
            f"  nonlinear run at {run['factor']:g} x ({number(run['gamma'], digits=3)}): "
            f"{verdict} ({detail})"
        )
    return lines


def write_spatial_report(
    summary: dict, out_dir: str | Path, overwrite: bool = True
) -> ResultFolder:
    """Writes report.json, report.txt and eigenvalues.png atomically."""
    return write_sampled_report(
        summary,
        out_dir,
        format_spatial_report(summary),
        "the reduced spatial loop's eigenvalues",
        overwrite=overwrite,
    )


def spatial_stability(
    scenario: SpatialScenario, out: Path, options: StabilityOptions, overwrite: bool, progress
) -> tuple[str, ResultFolder]:
    """`admittance stability` on a spatial arm: the report written to `out`, and its text.
    quick skips the nonlinear confirmation runs; without the trajectory there is nothing
    to skip (noted)."""
    summary = analyse_spatial_stability(scenario, confirm=not options.quick, progress=progress)
    notes = []
    if options.quick:
        notes.append("--quick: the nonlinear runs at 0.8 and 1.25 x were skipped")
    if not options.trajectory:
        notes.append("--no-trajectory: a spatial arm has no V(t) run; nothing to skip")
    summary["notes"] = notes
    progress(f"writing {out}/")
    folder = write_spatial_report(summary, out, overwrite=overwrite)
    text = format_spatial_report(summary) + "".join(f"Note: {note}\n" for note in notes)
    return text, folder
