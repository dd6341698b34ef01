"""The plant's fleet store (issue 31): the PostgreSQL schema and its migrations, its settings and
the fleet's queries.

May import station.errors only. Publishing a finished run from the station's run database (store
and forward) is the cell's: station.cell.publication.outbox, which calls this store.
"""
