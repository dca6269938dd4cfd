"""Planners for a team of UAVs (several ``agents:``), built from the planners of one UAV.

Each UAV of the team runs its own single-UAV planner on its own mission
(`hptrack.interface.MissionSpec.vehicle_mission`) and the shared beliefs; the team planner
says which targets the other UAVs have claimed (`hptrack.teams.link`: what each UAV knows of
the others' claims over the team's link), and those leave the UAV's action list while they are
claimed. `hptrack.teams.sequential` plans the UAVs one at a time, each seeing the claims of
those before it (multiagent rollout, Bhattacharya et al. 2020); `hptrack.teams.auction`
allocates the targets by CBBA (Choi, Brunet and How 2009) and lets each UAV search over its
bundle.
"""
