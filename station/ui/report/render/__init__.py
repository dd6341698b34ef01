"""The report drawn and written: the HTML page, the Markdown page, the plots (PNG) and the picture
of the cell with the plan's poses (SVG/PNG), each from the :mod:`station.ui.report.contents` it
is given.

May import: the rest of :mod:`station.ui.report`, :mod:`station.cell`, :mod:`station.core`,
matplotlib; never :mod:`station.ui.cli` or :mod:`station.ui.tui`.
"""
