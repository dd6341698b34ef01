"""The operator's terminal UI (Textual): screens, widgets, the result panel and its launcher.

May import report and station.cell; never cli's commands or drivers.
"""
