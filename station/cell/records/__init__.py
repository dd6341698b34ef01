"""The run database, its records and their checks, the run lock, export, fingerprint,
stored configuration and the run summary; a finished run's publication for the fleet store
(fleet_payload, fleet_outbox: store and forward).

May import config, plan (its step types), station.core, station.fleet (the store it publishes
to); never the runner, devices or UI.
"""
