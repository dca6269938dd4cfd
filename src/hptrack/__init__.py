"""hptrack: hierarchical planning for long-horizon multi-target tracking with one UAV.

Implements Yuan, Moon, Cao and Scherer, "Hierarchical Planning for Long-Horizon Multi-Target
Tracking Under Target Motion Uncertainty" (``docs/model.md``). SI units throughout:
metres, seconds, metres per second.
"""

import hptrack._numba_cache  # noqa: F401  (first: numba's cache directory, before any kernel)

__version__ = "0.1.0"
