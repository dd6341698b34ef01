"""The run database, its records and their checks, the run lock (a row of the same database,
taken in one transaction with the run it guards), export, fingerprint, stored configuration and
the run summary.

May import config, plan (its step types), station.core; never the runner, devices, the fleet store
or the UI.
"""
