"""The search's random stream: splitmix64 in one ``uint64`` array, so that its state lives in the
search (never in a global generator) and compiled code can draw from it."""

from __future__ import annotations

import numba
import numpy as np

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)


@numba.njit(cache=True)
def uniform(rng):
    """Next double in ``[0, 1)`` of the splitmix64 stream ``rng`` (one ``uint64``)."""
    rng[0] += _GOLDEN
    z = rng[0]
    z = (z ^ (z >> np.uint64(30))) * _MIX1
    z = (z ^ (z >> np.uint64(27))) * _MIX2
    z = z ^ (z >> np.uint64(31))
    return float(z >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@numba.njit(cache=True)
def substream(seed, k, out):
    """Start in ``out`` (one ``uint64``) the ``k``-th stream derived from ``seed``: the
    splitmix64 output of ``seed + (k + 1) * golden``, so distinct ``k`` give unrelated streams."""
    out[0] = seed + np.uint64(k + 1) * _GOLDEN
    uniform(out)  # one step scrambles the state; the stream goes on from there


def seed_value(seed: int | np.random.Generator) -> int:
    """The stream's initial state from an integer seed or a `numpy.random.Generator`
    (one ``uint64`` drawn from it)."""
    if isinstance(seed, np.random.Generator):
        return int(seed.integers(0, 2**63, dtype=np.uint64))
    return int(np.random.SeedSequence(seed).generate_state(1, np.uint64)[0])
