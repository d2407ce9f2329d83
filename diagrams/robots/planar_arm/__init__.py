"""The paper's 3-DOF planar arm pressing its compliant wall (eq. 4): everything that is
this robot's.
"""
