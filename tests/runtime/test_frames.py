import numpy as np
import pytest

from hptrack.runtime.frames import enu_to_ned, ned_to_enu


def test_enu_to_ned_swaps_axes_and_flips_altitude():
    assert enu_to_ned(3.0, 4.0, 30.0) == (4.0, 3.0, -30.0)
    assert ned_to_enu(4.0, 3.0, -30.0) == (3.0, 4.0, 30.0)


@pytest.mark.parametrize("point", [(1.5, -2.0, 7.0), (-100.0, 250.0, 0.0)])
def test_round_trip(point):
    np.testing.assert_array_equal(ned_to_enu(*enu_to_ned(*point)), point)
