"""The probe head: where its probes touch a cube and the pose they measure (``geometry``), and the
checks of a head and its readings (``check``).

May import ``kinematics``.
"""
