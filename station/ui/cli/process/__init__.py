"""What the `station` process needs around its commands, whatever the command: writes that a
closed pipe cannot fail (``output``), SIGTERM/SIGINT turned into an ABORTED run (``stop_signals``),
which library warnings reach the user (``warning_policy``), the libraries' log lines in the
station's log (``library_log``) and the progress clock (``progress_clock``).

May import station.errors and the standard library; never a command, the cell or a device.
"""
