"""The correction table: its values and axes as a controller holds them (``values``), the grid
and the controller's interpolation rule (``grid``), building it from an identified model
(``build``) and designing its region and steps (``design``).

May import ``terms`` (their compensation), ``identification``, ``measurement`` and ``kinematics``.
"""
