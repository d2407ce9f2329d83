"""Small 3-vector arithmetic on lists: the same code for floats and AutoDiffXd, and about
ten times faster than numpy's on 3-vectors (np.cross alone costs tens of us). The wrist
sensor's weight compensation and its reading in a control frame run it on every sample.
"""

from __future__ import annotations

__all__ = ["cross", "rotate", "rotation_rows", "unrotate"]


def cross(a, b) -> list:
    """a x b."""
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def rotate(R, v) -> list:
    """R v, R as three rows."""
    return [r[0] * v[0] + r[1] * v[1] + r[2] * v[2] for r in R]


def unrotate(R, v) -> list:
    """R^T v, R as three rows."""
    return [R[0][i] * v[0] + R[1][i] * v[1] + R[2][i] * v[2] for i in range(3)]


def rotation_rows(pose) -> list:
    """R_WB of a body pose X_WB as three rows."""
    return pose.rotation().matrix().tolist()
