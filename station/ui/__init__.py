"""What people use: the command line (cli/), the operator's terminal UI (tui/) and the report (report/).

cli → tui → report → simulated_cell, and all of them reach the devices only through station.cell.
"""
