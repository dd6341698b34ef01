"""The run's stream of facts (issue 42): the typed events the runner and the pipeline emit, the
stream that hands them to every subscriber in order, and the subscribers that are not views: the
run database's writers, progress "k of n", the next move's clearance.

May import: :mod:`station.cell.records`, :mod:`station.cell.plan`, :mod:`station.cell.config`,
:mod:`station.core` and :mod:`station.errors`; never the runner's devices or :mod:`station.ui`.
"""
