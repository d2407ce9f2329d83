"""The robots, one package each (``planar_arm``, ``planar_gripper``, ``spatial_arm``), and
what every robot's package shares: the description of a force-controlled point
(:mod:`.description`) and planar inverse kinematics (:mod:`.inverse_kinematics`).

Importing this package imports no robot: a robot's package is imported where it is used.
"""
