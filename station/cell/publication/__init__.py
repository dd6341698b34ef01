"""A finished run's publication for the plant's fleet store: what is published (``payload``,
built once from the run database) and the station's store-and-forward queue (``outbox``).

Beside the pipeline, below the session that publishes at a run's end. May import records, config,
plan, station.core and station.fleet (the store it publishes to); never the runner, devices or UI.
"""
