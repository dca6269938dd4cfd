"""Target motion, measurement and belief models (paper Sec. III, Eq. (1))."""

from hptrack.models.beliefs import TargetBeliefs, position_logdet
from hptrack.models.measurement import PositionMeasurementModel
from hptrack.models.motion import ConstantVelocityModel, ProcessNoiseForm

__all__ = [
    "ConstantVelocityModel",
    "PositionMeasurementModel",
    "ProcessNoiseForm",
    "TargetBeliefs",
    "position_logdet",
]
