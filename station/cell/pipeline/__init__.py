"""The calibration pipeline: from the plan through the measurements to the identified robot, its
correction and the verification (``calibration``: the SCARA's and the six-axis arm's shared run;
``articulated``: the six-axis arm's compensated targets; ``results``: what a finished pipeline
records; ``terms``: the error terms beyond geometry), its outcomes, the checks before the first
motion (``premotion``) and the plan preview.

May import correction, run, publication's neighbours below it (records, plan, limits, config) and
station.core/io; never the session, the UI or a simulator.
"""
