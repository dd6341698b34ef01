"""Error terms beyond geometry (drift, backlash, compliance, gear harmonics): their model
(``error_model``), their fit together with the geometry, their pose design, uncertainty and
compensation, and the model selection by cross-validation (``selection``).

May import ``identification``, ``measurement`` and ``kinematics``.
"""
