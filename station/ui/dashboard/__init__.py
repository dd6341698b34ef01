"""The QA dashboard (``station serve``): a read-only web app over the fleet store (issue 31).

May import station.fleet's store and overview, starlette and jinja2; never the cell, the run
database, devices or the rest of the UI.
"""
