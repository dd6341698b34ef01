"""The measurement plan: typed steps, the plan over the body for SCARA and six-axis arms.

May import config, limits, station.core and station.io; never the runner or the records.
"""
