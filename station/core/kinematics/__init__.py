"""The robot model and its kinematics: the model (``model``), transforms, forward kinematics with
Jacobians (``forward``), inverse kinematics (``ik``, ``ik_geometry``, ``ik_seeds``), joint maps and
offsets, tool frames, joint samples (``poses``) and the inverse compensation (``compensation``:
the commanded joints that make the identified robot reach a nominal target).

The bottom of the core: imports only ``station.core.units`` and ``station.errors``.
"""
