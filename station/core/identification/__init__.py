"""The identification: the fit kernel, identifiability (structural and numerical), the
registration of the set-up, the identification itself (``identify``) and the I-optimal pose
design (``pose_design``).

May import ``measurement`` and ``kinematics``.
"""
