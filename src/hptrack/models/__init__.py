"""Target motion, measurement and belief models (paper Sec. III, Eq. (1)): one compiled kernel per
formula (prediction over any duration, Kalman update with a full ``R``, Riccati compositions),
with a thin numpy API on top."""

from hptrack.models.belief_motion import (
    BeliefMotion,
    ConstantVelocity,
    OrnsteinUhlenbeckMotion,
    RandomWalkMotion,
)
from hptrack.models.beliefs import position_logdet
from hptrack.models.measurement import PositionMeasurementModel
from hptrack.models.motion import ConstantVelocityModel, ProcessNoiseForm

__all__ = [
    "BeliefMotion",
    "ConstantVelocity",
    "ConstantVelocityModel",
    "OrnsteinUhlenbeckMotion",
    "PositionMeasurementModel",
    "ProcessNoiseForm",
    "RandomWalkMotion",
    "position_logdet",
]
