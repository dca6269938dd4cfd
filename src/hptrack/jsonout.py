"""Strict JSON for every file hptrack writes: command summaries (``--json``), the results
store's per-episode info, episode records' metadata, mission logs and the coverage reports.

Numpy arrays and tuples become lists, numpy scalars Python numbers, and a number that is not
finite becomes the string ``"inf"``, ``"-inf"`` or ``"nan"`` (the form planner settings use for
"no limit", e.g. ARVI's first ``delta``): every file is strict JSON (RFC 8259) that any reader
loads, and `hptrack.runtime.log.log_float` (or Python's ``float``) reads such a string
back as the number. A figure that is not defined (a MAPE over no case) is written ``"nan"``.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np


def json_ready(value: Any) -> Any:
    """``value`` as strict-JSON data: arrays and tuples as lists, numpy scalars as Python
    numbers, non-finite floats as ``"nan"``/``"inf"``/``"-inf"``."""
    if isinstance(value, np.ndarray):
        return json_ready(value.tolist())
    if isinstance(value, dict):
        return {str(k): json_ready(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_ready(v) for v in value]
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        value = float(value)
        return value if math.isfinite(value) else str(value)
    return value


def json_text(value: Any, indent: int | None = None) -> str:
    """``value`` as strict JSON text (`json_ready`), indented by ``indent`` spaces."""
    return json.dumps(json_ready(value), indent=indent, allow_nan=False)
