"""A cell's sessions: opening a cell and running a calibration on it from loading to its summary
(``calibrate``, resumable), and a new cell's configuration derived from its own files
(``new_cell``: ``station init``).

May import pipeline, publication and everything below them in the cell; never the UI.
"""
