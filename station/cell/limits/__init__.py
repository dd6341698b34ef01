"""The motion guard (soft limits, finite targets) and joint values as people read them.

May import station.core only: every layer above asks it before a motion.
"""
