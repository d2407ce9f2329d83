"""The grasp's figure: the three normal forces against their Fr, and the brick's drop."""

from __future__ import annotations

import matplotlib.pyplot as plt

from admittance.diagrams.robots.planar_gripper.run import DROP_LIMIT, GraspResult
from admittance.diagrams.robots.planar_gripper.scenario import FINGERS

__all__ = [
    "plot_grasp",
]


def plot_grasp(result: GraspResult, axes=None):
    """The three normal forces against their Fr (above) and the brick's drop (below)."""
    if axes is None:
        _, axes = plt.subplots(2, 1, sharex=True, figsize=(8, 6))
    columns = result.columns()
    t = columns["time"]
    for finger, color in zip(FINGERS, ("C0", "C1", "C2"), strict=True):
        axes[0].plot(t, columns[f"{finger}_force"], color=color, label=f"{finger} F")
        axes[0].plot(
            t, columns[f"{finger}_force_reference"], color=color, ls="--", lw=1, label="Fr"
        )
    axes[0].set_ylabel("normal force (N)")
    axes[0].legend(loc="upper right", ncol=3, fontsize="small")
    axes[0].grid(True, alpha=0.3)
    hold = result.metrics.get("hold_start")
    axes[1].plot(t, 1e3 * columns["brick_drop"], color="k", label="brick drop")
    axes[1].axhline(1e3 * DROP_LIMIT, color="r", ls=":", lw=1, label="drop limit")
    for axis in axes:
        if hold is not None:
            axis.axvline(hold, color="0.5", lw=0.8)
    axes[1].set_ylabel("drop since the hold start (mm)")
    axes[1].set_xlabel("time (s)")
    axes[1].legend(loc="upper right", fontsize="small")
    axes[1].grid(True, alpha=0.3)
    scenario = result.scenario
    axes[0].set_title(
        f"{scenario.name} ({scenario.controller.kind}): {result.metrics.get('outcome', '')}"
    )
    return axes
