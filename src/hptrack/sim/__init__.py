"""Mission simulation: true world, agent kinematics, sensing, the episode loop and its record.

Import from the submodules: :mod:`hptrack.sim.step` (one compiled step and the simulated
:class:`~hptrack.sim.step.World`), :mod:`hptrack.sim.episode` (the loop) and
:mod:`hptrack.sim.record` (the episode record). What planners see is in :mod:`hptrack.interface`.
"""
