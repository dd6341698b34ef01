"""What is measured and how sure it is: measurement sets and the measurement equation
(``measurements``), distance pairs, and the propagation of measurement and body uncertainty to
parameters and poses (``uncertainty``: linear, sandwich, Monte Carlo).

May import ``kinematics``.
"""
