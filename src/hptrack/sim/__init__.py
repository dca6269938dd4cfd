"""Mission simulation: true world, agent kinematics, sensing, the episode loop and its record.

Import from the submodules: `hptrack.sim.step` (one compiled step and the simulated
`World`), `hptrack.sim.episode` (the loop) and
`hptrack.sim.record` (the episode record). What planners see is in `hptrack.interface`.
"""
