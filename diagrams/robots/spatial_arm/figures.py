"""The spatial arm's figure: the force along the planned normal against Fr, and the tool's
path and orientation errors over the run."""

from __future__ import annotations

import matplotlib.pyplot as plt

from admittance.diagrams.robots.spatial_arm.run import SpatialResult

__all__ = ["plot_spatial"]


def plot_spatial(result: SpatialResult, axes=None):
    """The force against Fr (above), the path and orientation errors (below)."""
    if axes is None:
        _, axes = plt.subplots(2, 1, sharex=True, figsize=(8, 6))
    t = result.time
    axes[0].plot(t, result.force, color="C0", label="F (true, along the planned normal)")
    axes[0].plot(t, result.force_measured, color="C2", lw=0.8, label="F measured")
    axes[0].plot(t, result.force_reference, color="k", ls="--", lw=1, label="Fr")
    axes[0].set_ylabel("force (N)")
    axes[0].legend(loc="lower right", fontsize="small")
    axes[1].plot(t, 1e3 * result.path_error, color="C1", label="path error (mm)")
    axes[1].plot(t, result.orientation_error, color="C3", label="orientation error (deg)")
    axes[1].set_ylabel("error")
    axes[1].set_xlabel("time (s)")
    axes[1].legend(loc="upper right", fontsize="small")
    window = result.metrics.get("slide_window")
    for axis in axes:
        axis.grid(True, alpha=0.3)
        if window is not None:
            axis.axvspan(*window, color="0.9", zorder=0)
    scenario = result.scenario
    axes[0].set_title(f"{scenario.name} ({scenario.controller.kind})")
    return axes
