"""The plant's fleet store (issue 31): the PostgreSQL schema and its migrations, publishing a
finished run from the station's run database (store and forward), and the fleet's queries.

May import station.cell.records and station.cell.config, station.core; never the runner, the
devices, the sessions or the UI.
"""
