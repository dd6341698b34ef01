"""The correction: its design and pre-motion check (design.py), the upload and the operator's
table, tools.

May import run, records, plan, config and station.core; never results or sessions.
"""
