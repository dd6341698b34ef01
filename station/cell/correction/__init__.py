"""The correction: its design (design.py) and pre-motion check (precheck.py, with the checked
advice of advice.py), the upload and the operator's table, tools.

May import run, records, plan, config and station.core; never results or sessions.
"""
