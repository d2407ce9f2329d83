"""Drake's planar gripper holding a brick through Drake's contact engine, one admittance
loop per finger: everything that is this robot's.
"""
