"""Gymnasium environments of the tracking problem (optional extra ``hptrack[envs]``).

Importing this package registers them (Gymnasium 1.x has no plugin entry points):

* ``hptrack/Tracking-v0``: one simulator step per action (`hptrack.envs.tracking`);
* ``hptrack/SubtaskTracking-v0``: one coverage sub-task per action (`hptrack.envs.subtask`);
* ``hptrack/TeamTracking-v0``: one simulator step of a team per action, every UAV's action in
  it (`hptrack.envs.team`).

``gym.make("hptrack.envs:Tracking-v0")`` imports this package and then looks up the name after
the colon, so they are also registered without the namespace (``Tracking-v0``,
``SubtaskTracking-v0``, ``TeamTracking-v0``).
"""

from __future__ import annotations

import gymnasium as gym

from hptrack.envs.observation import ObservationLayout
from hptrack.envs.subtask import SubtaskTrackingEnv
from hptrack.envs.team import TeamTrackingEnv
from hptrack.envs.tracking import HOVER, MissionEnv, TrackingEnv, action_waypoint

ENTRY_POINTS = {
    "Tracking-v0": "hptrack.envs.tracking:TrackingEnv",
    "SubtaskTracking-v0": "hptrack.envs.subtask:SubtaskTrackingEnv",
    "TeamTracking-v0": "hptrack.envs.team:TeamTrackingEnv",
}
"""Environment name -> entry point; each is registered as ``hptrack/<name>`` and ``<name>``."""


def _register() -> None:
    for name, entry_point in ENTRY_POINTS.items():
        for env_id in (f"hptrack/{name}", name):
            if env_id not in gym.registry:
                gym.register(id=env_id, entry_point=entry_point)


_register()

__all__ = [
    "ENTRY_POINTS",
    "HOVER",
    "MissionEnv",
    "ObservationLayout",
    "SubtaskTrackingEnv",
    "TeamTrackingEnv",
    "TrackingEnv",
    "action_waypoint",
]
