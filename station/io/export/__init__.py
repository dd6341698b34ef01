"""Writing an identified model into the files its consumers read: the station's TOML, DH/MDH
tables, the robot's own URDF with calibrated joint origins, and UR's ROS 2 kinematics YAML.

May import: :mod:`station.core`, :mod:`station.io.robot`, :mod:`station.errors`, the standard
library and the writers' libraries; never :mod:`station.cell` or :mod:`station.ui`.
"""
