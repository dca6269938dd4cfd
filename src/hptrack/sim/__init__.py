"""Mission simulation: true world, agent kinematics, sensing, the episode loop and its record."""

from hptrack.sim.episode import run_episode
from hptrack.sim.interface import MissionSpec, Observation, Planner
from hptrack.sim.record import EpisodeRecord

__all__ = ["EpisodeRecord", "MissionSpec", "Observation", "Planner", "run_episode"]
