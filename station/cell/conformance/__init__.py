"""The conformance kit: requirement by requirement, does a robot program implement the map?

May import config, limits, station.core and drivers; never the runner, records or sessions.
"""
