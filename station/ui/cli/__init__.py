"""The command line: the parser, the commands, their output, signals and warning policy.

May import report, tui (lazily, for `station ui`) and station.cell; never drivers.
"""
