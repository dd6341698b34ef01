"""The verification paths as the controller will move them, checked once the robot is identified and
before any verification motion (issue 40): the plan's pre-motion check saw the planned joints, but
after identification the runner commands other joints.

* ``shifted_check`` — a SCARA's path with the correction table's Δq added (and the oracle's table);
* ``compensated_check`` — an articulated arm's path at the joints of its compensated targets;
* ``plain_check`` — an arm's verification before correction, in the frame the uncorrected robot
  located the body in.

Each refuses a clash with :class:`~station.cell.plan.moved_path.shifted_check.ShiftedPathCollides`
(exit 2). May import the plan's lower layers (measurement_plan, vias, collision, steps), the cell's
config and limits, and the core; nothing of the run, the pipeline or the UI.
"""
