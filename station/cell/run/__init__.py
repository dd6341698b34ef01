"""The runner and what it owns: devices' Protocols, events, run control, re-centring,
stuck probes, warm-up, the operator's questions and the pre-motion device check.

May import records, plan, limits, config, station.core/io and drivers' data types; never results.
"""
