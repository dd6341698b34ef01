"""From measurements to results: the pipelines (SCARA, six-axis), outcomes, the plan preview.

May import correction, run, records, plan, limits, config and station.core/io.
"""
