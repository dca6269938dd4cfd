"""The fortified decision rule of rollout over a base policy (Bertsekas, Tsitsiklis and Wu,
"Rollout algorithms for combinatorial optimization", J. Heuristics, 1997): keep the base
policy's action unless the search has found a better one.

A search's value estimates are noisy; switching away from the base policy's action on a
difference smaller than that noise would trade a plan that is known to be good for one that
only looks better by chance. The search's best action replaces the base's only when its value
beats the base's by more than the standard error of the difference of their mean returns
(`hptrack.planning.tree.ActionStats.standard_errors`).
"""

from __future__ import annotations

import math

from hptrack.planning.tree import ActionStats


def fortified_choice(stats: ActionStats | None, base: int) -> int | None:
    """The action to take at a searched state: ``base`` (the base policy's action; ``-1``:
    none) unless the search's best (``stats.best``) beats it by more than the standard error
    of the difference; the search's best when the base was never searched; ``None`` when
    there are no statistics and no base."""
    best = None if stats is None else stats.best
    if best is None:
        return base if base >= 0 else None
    assert stats is not None
    at_base = stats.of(base)
    if base < 0 or at_base is None or stats.visits[at_base] == 0:
        return best
    at_best = stats.of(best)
    assert at_best is not None
    errors = stats.standard_errors()
    margin = math.hypot(errors[at_best], errors[at_base])
    return best if stats.values[at_best] - stats.values[at_base] > margin else base
