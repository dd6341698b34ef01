"""The calibration report: data gathered from the run database, HTML and Markdown pages, plots.

Reads summaries and the run database through station.cell; never devices, cli or tui.
"""
