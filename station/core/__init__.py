"""The numerical core: pure numerics, arrays in, frozen results out (mm and rad inside).

Sub-packages in layers, top to bottom (pyproject's import contracts keep the order):

- ``accuracy``: ISO 9283 figures and the chapter's simulation studies;
- ``table``: the correction table: its values as a controller holds them, its grid and
  interpolation, how it is built from an identified model and how it is designed;
- ``terms``: the error terms beyond geometry (drift, backlash, compliance, gear harmonics): their
  model, fit, design, uncertainty, compensation and selection by cross-validation;
- ``identification``: the fit kernel, identifiability, registration of the set-up, the
  identification itself and the I-optimal pose design;
- ``measurement``: what is measured (measurement sets, distance pairs) and how its uncertainty
  propagates (linear, sandwich, Monte Carlo); ``probe``: the probe head's geometry and checks;
- ``kinematics``: the robot model, transforms, forward and inverse kinematics, joint maps and
  offsets, tool frames and the inverse compensation.

``units`` and ``blas_threads`` serve every layer. The core imports no driver, device, file or UI.
"""
