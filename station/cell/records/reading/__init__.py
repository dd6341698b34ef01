"""What is read back from the run database for people and scripts: a run's configuration and
plan as it was made with them, its stored error model, the list of runs, the CSV export of its
measurements.

May import: the rest of :mod:`station.cell.records`, :mod:`station.cell.config`,
:mod:`station.cell.plan`, :mod:`station.io`, :mod:`station.core` and :mod:`station.errors`.
"""
