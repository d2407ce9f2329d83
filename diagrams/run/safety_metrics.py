"""The safety layer's logs as metrics, for every robot: each detection's time and kind,
the layer's timeseries columns, the first detection of an injected fault, the stiffness
estimate beyond the stated bound.
"""

from __future__ import annotations

import math

import numpy as np

from admittance.diagrams.loop.layer_systems import (
    STIFFER_FACTOR,
)
from admittance.systems.fault_detector import FAULT_FLAGS

__all__ = [
    "fault_detection",
    "rising_edges",
    "safety_columns",
    "stiffer_than_stated",
    "wall_approach_detections",
]


def rising_edges(time: np.ndarray, flags: np.ndarray) -> list[dict]:
    """Each time a flag turns on: {"time", "kind"}, in time order (the columns: the
    detector's FAULT_FLAGS, then its collision flag)."""
    detections = []
    for column, kind in enumerate(FAULT_FLAGS + ("collision",)):
        on = flags[:, column] > 0.5
        starts = np.nonzero(on & ~np.concatenate([[False], on[:-1]]))[0]
        detections += [{"time": float(time[i]), "kind": kind} for i in starts]
    return sorted(detections, key=lambda d: d["time"])


def safety_columns(logs: dict) -> dict[str, np.ndarray]:
    """The layer's timeseries.csv columns (after the paper's)."""
    columns = {
        "force_trusted": logs["trusted_force"][:, 0],
        "force_observed": logs["observed_force"][:, 0],
        "stiffness_estimate": logs["stiffness_estimate"][:, 0],
        "gain_scale": logs["gain_scale"][:, 0],
    }
    for column, kind in enumerate(FAULT_FLAGS):
        columns[f"fault_{kind}"] = logs["fault_flags"][:, column]
    columns["collision"] = logs["collision"][:, 0]
    return columns


def wall_approach_detections(time, logs, scenario) -> list[dict]:
    """Each time the wall's approach speed v_hat (systems/wall_motion_monitor.py) rises
    above v_f = v_max (Fmax - Fr) / Fmax at the run's start: {"time", "kind":
    "wall_approaching", "speed": v_hat}."""
    max_force = scenario.admittance.max_force
    follow = logs["numbers"]["approach_speed"] * (max_force - scenario.force_reference) / max_force
    speed = np.asarray(logs["wall_approach_speed"])[:, 0]
    on = speed > follow
    starts = np.nonzero(on & ~np.concatenate([[False], on[:-1]]))[0]
    return [
        {"time": float(time[i]), "kind": "wall_approaching", "speed": float(speed[i])}
        for i in starts
    ]


def stiffer_than_stated(time, estimate, max_stiffness: float) -> dict | None:
    """The first logged sample whose stiffness estimate is above STIFFER_FACTOR x Ke_max:
    {"time", "estimate", "threshold"}; None if there is none."""
    threshold = STIFFER_FACTOR * max_stiffness
    above = np.nonzero(np.asarray(estimate) > threshold)[0]
    if above.size == 0:
        return None
    row = above[0]
    return {"time": float(time[row]), "estimate": float(estimate[row]), "threshold": threshold}


def fault_detection(detections: list[dict], start: float, end: float) -> dict:
    """The first detection during [start, end] of an injected fault: time, kind, delay."""
    for detection in detections:
        if detection["kind"] == "wall_approaching":
            continue  # the wall's motion, not the sensor's
        if start <= detection["time"] <= end + math.ulp(end):
            return {
                "detected_time": detection["time"],
                "detected_kind": detection["kind"],
                "detection_delay": detection["time"] - start,
            }
    return {"detected_time": None, "detected_kind": None, "detection_delay": None}
