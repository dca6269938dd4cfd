"""Flying a mission in real time: the mission controller (no vehicle or middleware inside), its
JSON-lines log and replay, the simulated-clock runner with faults, and the adapters (MAVSDK
offboard control, a pymavlink vehicle stub), which import their optional packages themselves.
"""

from hptrack.runtime.controller import MissionController, Setpoint
from hptrack.runtime.frames import enu_to_ned, ned_to_enu
from hptrack.runtime.inputs import ControllerSettings
from hptrack.runtime.log import MissionLog, read_log
from hptrack.runtime.simulated import SimulatedFaults, SimulatedRun, run_simulated

__all__ = [
    "ControllerSettings",
    "MissionController",
    "MissionLog",
    "Setpoint",
    "SimulatedFaults",
    "SimulatedRun",
    "enu_to_ned",
    "ned_to_enu",
    "read_log",
    "run_simulated",
]
