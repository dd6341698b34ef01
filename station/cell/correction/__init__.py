"""The correction: the pre-motion grid check, the upload and the operator's table, tools.

May import run, records, plan, config and station.core; never results or sessions.
"""
