"""The run database, its records and their checks, the run lock, export, fingerprint,
stored configuration and the run summary.

May import config, plan (its step types), station.core; never the runner, devices or UI.
"""
