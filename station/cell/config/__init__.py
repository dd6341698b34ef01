"""The cell configuration: its schema, its loader, the sections' dataclasses and the template `station init` writes.

May import station.core, station.io and the drivers' data tables (probe dialects, table capacity); nothing else of the cell.
"""
