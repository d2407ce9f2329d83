"""The report folder of a sampled loop's stability: report.json, report.txt and its
eigenvalues against the unit circle (the gripper's and the spatial arm's).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from admittance.diagrams.results.folder import ResultFolder, result_folder

__all__ = ["unit_circle_figure", "write_sampled_report"]


def unit_circle_figure(eigenvalues, title: str):
    """A sampled loop's eigenvalues (rows of [Re z, Im z]) against the unit circle."""
    eigenvalues = np.array(eigenvalues)
    figure, ax = plt.subplots(figsize=(5, 5))
    angle = np.linspace(0, 2 * np.pi, 400)
    ax.plot(np.cos(angle), np.sin(angle), "k-", lw=0.8, label="unit circle")
    ax.scatter(eigenvalues[:, 0], eigenvalues[:, 1], marker="x")
    ax.set_aspect("equal")
    ax.set_xlabel("Re z")
    ax.set_ylabel("Im z")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower left")
    return figure


def write_sampled_report(
    summary: dict, out_dir: str | Path, text: str, title: str, overwrite: bool = True
) -> ResultFolder:
    """Writes report.json, report.txt (`text`) and eigenvalues.png (`title`) atomically."""
    with result_folder(out_dir, overwrite=overwrite) as folder:
        folder.write_json("report.json", summary)
        folder.write_text("report.txt", text)
        figure = unit_circle_figure(summary["modes"]["eigenvalues"], title)
        folder.write_figure("eigenvalues.png", figure, dpi=100)
    return folder
