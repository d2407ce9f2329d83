"""A published serial arm (the Franka Panda, the UR5) whose tool presses and slides on a
table in six dimensions: everything that is this robot's.
"""
