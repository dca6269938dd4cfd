"""Mission simulation: true world, agent kinematics, sensing, the episode loop and its record.

Import from the submodules: :mod:`hptrack.interface` (what planners see),
:mod:`hptrack.sim.episode` (the loop) and :mod:`hptrack.sim.record` (the episode record).
"""
