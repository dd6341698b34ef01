"""The cell: one calibration cell's configuration, plan, runner, records, correction and results.

Sub-packages in layers, top to bottom (pyproject's import contracts keep the order):
recheck | conformance → session → pipeline | publication → correction → run → records → plan →
limits | config.
"""
