"""Files users bring and files the station writes for them: the cell's body (CMM report), probe
head, measurement and joint data, certificates' identities; robot files in :mod:`station.io.robot`,
model exports in :mod:`station.io.export`.

May import: :mod:`station.core`, :mod:`station.errors` and file parsers; never :mod:`station.cell`,
:mod:`station.ui`, drivers or simulators (the layers' contract in pyproject.toml).
"""
