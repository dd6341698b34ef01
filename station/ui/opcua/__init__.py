"""The station as a secure OPC UA server for the line's PLC and MES (``station serve --opcua``).

model.py loads the OPC Foundation's NodeSet2 files (nodesets/, kept as published, with their
licence and versions) and the station's own (nodesets/Station.NodeSet2.xml, made by typegen.py)
and instantiates the robot, the calibration body and the station; service.py runs calibrations
and rechecks through the same sessions as the CLI and the TUI, one at a time, in a worker thread;
security.py holds the certificates, the users (scrypt hashes or user certificates) and the roles.

A client of the runner beside cli/ and tui/: may import station.cell, station.ui.simulated_cell,
station.errors and asyncua; never cli, tui, report or drivers; nothing in station.cell or below
imports it (pyproject.toml's import contracts).
"""
