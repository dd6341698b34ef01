"""The recheck: re-measuring held-out poses against a baseline run, and its session.

May import session and everything below it in the cell; never conformance or the UI.
"""
