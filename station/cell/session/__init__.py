"""The calibrate session: one run from loading the cell to its summary, resumable.

May import results and everything below it in the cell; never the UI.
"""
