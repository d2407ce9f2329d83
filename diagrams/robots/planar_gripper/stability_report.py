"""`admittance stability` on a grasp scenario: the sampled hand at its held grasp.

The analysis is the package's ``analysis``; this writes report.json, report.txt and the
eigenvalues against the unit circle through the result-folder writer.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from admittance.diagrams.results.folder import ResultFolder
from admittance.diagrams.robots.planar_gripper.analysis import analyse_grasp
from admittance.diagrams.robots.planar_gripper.scenario import GraspScenario
from admittance.diagrams.robots.record import StabilityOptions
from admittance.diagrams.views.formatting import number
from admittance.diagrams.views.sampled_report import write_sampled_report

__all__ = [
    "analyse_grasp_stability",
    "format_grasp_report",
    "grasp_stability",
    "write_grasp_report",
]


def _silent(stage: str) -> None:
    pass


def analyse_grasp_stability(
    scenario: GraspScenario, *, progress: Callable[[str], None] = _silent
) -> dict:
    """Everything `admittance stability` reports for a grasp (report.json's content)."""
    return analyse_grasp(scenario, progress=progress)


def format_grasp_report(summary: dict) -> str:
    """report.txt: the method, the held grasp, the modes, the certificate, each finger's
    critical Gamma and its nonlinear check, and the notes."""
    h = summary["time_step"]
    lines = [
        f"Stability of grasp scenario {summary['scenario']}",
        "",
        f"The sampled loop over one period (h = {number(h, ' s')}): x[k+1] = f(x[k]), "
        f"{summary['num_states']} discrete states, A = df/dx by central differences of one "
        f"simulator step (relative step {number(summary['relative_step'])}).",
        "",
        *_held_grasp_lines(summary["equilibrium"]),
        "",
        *_mode_lines(summary, h),
        _lyapunov_line(summary["lyapunov"]),
        *_critical_lines(summary),
    ]
    confirmation = summary.get("confirmation")
    if confirmation:
        below, above = confirmation["below"], confirmation["above"]
        lines.append(
            "Nonlinear check, all fingers (a 0.5 mm nudge of every Xr): at "
            f"{number(below['gamma'], digits=3)} converges = {below['converges']}, at "
            f"{number(above['gamma'], digits=3)} converges = {above['converges']} "
            f"(contact lost: {above['contact_lost']})"
        )
    for note in summary.get("notes", []):
        lines.append(f"Note: {note}")
    return "\n".join(lines) + "\n"


def _held_grasp_lines(equilibrium: dict) -> list[str]:
    """The held grasp: its residual, the brick's pose and creep, each finger's forces."""
    lines = [
        f"Held grasp at t = {number(equilibrium['time'], ' s')} (simulated, then Newton on "
        "f(x) = x): "
        f"residual max |f(x) - x| / h = {number(equilibrium['residual'], digits=2)} "
        f"(before the polish {number(equilibrium['settled_residual'], digits=2)})",
        "  brick (y, z, theta) = ("
        + ", ".join(number(v, digits=4) for v in equilibrium["brick_pose"])
        + "), creeping at ("
        + ", ".join(number(v, digits=2) for v in equilibrium["brick_velocity"])
        + ") m/s, rad/s",
    ]
    for finger in equilibrium["fingers"]:
        x, y = finger["tip_position"]
        lines.append(
            f"  {finger['finger']}: normal force {number(finger['normal_force'], ' N', digits=5)} "
            f"(Fr {number(finger['force_reference'], ' N')}, error "
            f"{number(finger['force_error'], ' N', digits=2)}), tip ({number(x, digits=5)}, "
            f"{number(y, digits=3)}) m in its face frame, Xr "
            f"{number(finger['reference_offset'], ' m', digits=4)}"
        )
    return lines


def _mode_lines(summary: dict, h: float) -> list[str]:
    """The eigenvalues z (and s = ln(z) / h): the near-neutral modes apart, the others'
    stability."""
    modes = summary["modes"]
    resolved = summary["resolved_modes"]
    neutral = summary["near_neutral_modes"]
    lines = [
        f"Eigenvalues z: spectral radius {number(modes['spectral_radius'], digits=9)} "
        f"(stable: {modes['stable']}), {modes['zero_eigenvalues']} at z = 0 (held samples); "
        f"least damping ratio {number(modes['least_damped_ratio'])}",
        f"  {len(neutral['eigenvalues'])} near-neutral modes (|ln z| / h < "
        f"{number(neutral['resolution'], ' 1/s')}: the brick's free directions), growth "
        "rates " + ", ".join(number(g, " 1/s", digits=2) for g in neutral["growth_rates"]),
        f"  the other modes: stable {resolved['stable']}, spectral radius "
        f"{number(resolved['spectral_radius'], digits=6)}, slowest time constant "
        f"{number(resolved['slowest_time_constant'], ' s', digits=4)}",
        "  eigenvalues z and s = ln(z) / h (1/s), largest |z| first:",
    ]
    for real, imag in modes["eigenvalues"]:
        line = f"    {real:12.9f} {imag:+12.9f} j"
        if abs(complex(real, imag)) > 1e-12:
            s = np.log(complex(real, imag)) / h
            line += f"   s = {s.real:12.6g} {s.imag:+12.6g} j"
        lines.append(line)
    return lines


def _lyapunov_line(lyapunov: dict) -> str:
    """The discrete certificate without the near-neutral modes, or why there is none."""
    if lyapunov.get("positive_definite"):
        return (
            f"Lyapunov (discrete, without the near-neutral modes, {lyapunov['num_states']} "
            "states): A^T P A - P = -I has P > 0 (min eigenvalue "
            f"{number(lyapunov['min_eigenvalue'])}, condition number "
            f"{number(lyapunov['condition_number'])})"
        )
    return f"Lyapunov: no positive definite P ({lyapunov.get('error', 'P not > 0')})"


def _critical_lines(summary: dict) -> list[str]:
    """Each finger's critical Gamma (the others kept), and all three's together."""
    lines = [
        f"Critical Gamma (the scenario's {number(summary['gamma'])}; one finger's scaled, the "
        "others kept):"
    ]
    for name, entry in summary["critical_gamma"].items():
        label = "all three together" if name == "all" else name
        if entry["critical_gamma"] is None:
            lines.append(f"  {label}: none up to 1e-2")
        else:
            lines.append(
                f"  {label}: {number(entry['critical_gamma'], digits=4)} "
                f"({number(entry['margin'], digits=3)} x)"
            )
    return lines


def write_grasp_report(summary: dict, out_dir: str | Path, overwrite: bool = True) -> ResultFolder:
    """Writes report.json, report.txt and eigenvalues.png atomically."""
    return write_sampled_report(
        summary,
        out_dir,
        format_grasp_report(summary),
        "the sampled hand's eigenvalues at the held grasp",
        overwrite=overwrite,
    )


def grasp_stability(
    scenario: GraspScenario, out: Path, options: StabilityOptions, overwrite: bool, progress
) -> tuple[str, ResultFolder]:
    """`admittance stability` on a grasp: the report written to `out`, and its text. The
    options that do not apply to a grasp (quick: no stability maps, no trajectory: no V(t)
    run) are noted in the report, not refused."""
    notes = [
        f"{flag}: {reason}"
        for flag, given, reason in (
            ("--quick", options.quick, "a grasp has no stability maps (no wall to sweep); skipped"),
            (
                "--no-trajectory",
                not options.trajectory,
                "a grasp has no V(t) run; nothing to skip",
            ),
        )
        if given
    ]
    summary = analyse_grasp_stability(scenario, progress=progress)
    summary["notes"] = notes
    progress(f"writing {out}/")
    folder = write_grasp_report(summary, out, overwrite=overwrite)
    return format_grasp_report(summary), folder
