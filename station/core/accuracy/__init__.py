"""Accuracy figures: ISO 9283 pose accuracy and repeatability (``iso9283``) and the chapter's
simulation studies re-run with the core (``studies``).

May import every other core sub-package.
"""
