"""The Consensus-Based Bundle Algorithm (CBBA: Choi, Brunet and How, "Consensus-Based
Decentralized Auctions for Robust Task Allocation", IEEE T-RO 25(4), 2009), as a synchronous
simulation of the agents' rounds (``docs/teams.md``, "Allocating targets to a team").

Each agent ``i`` keeps its bundle ``b_i`` (tasks in the order it added them), its path ``p_i``
(the same tasks in flying order), the winning bids ``y_i`` and winners ``z_i`` it believes
(per task; ``z = -1``: nobody) and timestamps ``s_i`` (per agent: the round of the latest
information it has from that agent). A round is the paper's two phases, for every agent at once:

1. **Bundle construction.** The marginal score of task ``j`` is the best increase of the path's
   value over the insertion positions, ``c_ij = max_n S_i(p_i (+)_n j) - S_i(p_i)``. While the
   bundle has room, the agent adds the task of the highest ``c_ij`` among those it would win,
   ``c_ij > y_ij`` (or equal, against a higher-index winner), at its best position, bidding
   ``y_ij = c_ij``, ``z_ij = i``.
2. **Consensus.** Every agent sends ``(y, z, s)`` as they stand after phase 1 to the agents that
   hear it this round, and each receiver applies, task by task and sender by sender (lowest
   index first), the paper's Table I of update (take the sender's bid and winner), reset
   (nobody) and leave (keep its own), decided on who the sender and the receiver think wins and
   on whose information is newer (the timestamps). Then the timestamps advance: ``s_ik`` is the
   round if ``i`` heard ``k``, else the newest ``s_mk`` among the agents ``m`` it heard (or its
   own). Last the bundle is released from the first task the agent no longer wins: that task and
   every later one leave the bundle and path, and the later ones it still believed won are
   reset (their bids assumed the outbid task in the path).

Ties are broken by the lowest agent index (between bids) and the lowest task index (within an
agent's choice), so the run is deterministic. It has converged when a round changes no bundle,
bid or winner and every agent holds the same bids and winners (then every later round would
change nothing, whatever the links).

**Bid warping** (Johnson, Choi, Ponda and How, "Allowing Non-Submodular Score Functions in
Distributed Task Allocation", IEEE CDC 2012; on by default): an agent still chooses by the
marginal score, but bids ``min(c_ij, y_i,last)``, at most its bundle's last bid, so that its
bids never rise along its bundle, as diminishing marginal gains would make them. Under
diminishing gains it changes nothing; otherwise it is what makes the auction converge (without
it CBBA cycles on scores that reward a longer path, `hptrack.planning.team_value`'s among them).

A committed task (the one a UAV is flying) is first in its agent's bundle and path from the
start, every agent knows it is that agent's with an infinite bid, and nobody may insert a task
before it. Under diminishing marginal gains (a task's marginal score never rises as the path
grows) CBBA converges to the allocation of the sequential greedy assignment, within
``min(n_tasks, max_bundle * n_agents) * D`` rounds on a fixed network of diameter ``D`` (the
paper's Theorem 1; one more round here to see that nothing changes), and so is worth at least
half the optimum; otherwise the warped bids still converge (Johnson et al.) but the bound is
lost, and `Allocation.converged` says whether the run stopped by converging.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

NOBODY = -1
"""The winner of an unassigned task."""

PathValue = Callable[[int, tuple[int, ...]], float]
"""``path_value(agent, path)``: the value of an agent flying the tasks ``path`` in that order."""


@dataclass(frozen=True, eq=False)
class Allocation:
    """The result of `cbba`.

    Attributes:
        paths: per agent, its tasks in flying order.
        bundles: per agent, its tasks in the order it added them.
        winners: ``(n_tasks,)`` the agent of each task, ``-1`` unassigned (the agents agree on it
            once converged; otherwise the highest bid among the agents that claim the task).
        bids: ``(n_tasks,)`` the winning bid: the winner's marginal score when it added the
            task (with ``warp_bids``, at most its bundle's previous bid), 0 unassigned; a
            committed task's is its value alone, ``path_value(i, (j,)) - path_value(i, ())``.
        rounds: rounds run.
        converged: whether the last round changed nothing and the agents agree; if not, two
            paths may share a task.
    """

    paths: tuple[tuple[int, ...], ...]
    bundles: tuple[tuple[int, ...], ...]
    winners: np.ndarray
    bids: np.ndarray
    rounds: int
    converged: bool


def _beats(bid: float, agent: int, other_bid: float, other_agent: int) -> bool:
    """Whether ``agent``'s ``bid`` wins over ``other_agent``'s (``-1``: nobody): higher, or
    equal from a lower index."""
    if bid != other_bid:
        return bid > other_bid
    return other_agent != NOBODY and agent < other_agent


class _Agent:
    """One agent's knowledge (module docstring)."""

    def __init__(self, index: int, n_agents: int, n_tasks: int) -> None:
        self.index = index
        self.bundle: list[int] = []
        self.path: list[int] = []
        self.bids = np.zeros(n_tasks)
        self.winners = np.full(n_tasks, NOBODY, dtype=np.int64)
        self.stamps = np.zeros(n_agents, dtype=np.int64)
        self.first_free = 0  # the first path position a task may be inserted at

    def marginal(self, path_value: PathValue, task: int, base: float) -> tuple[float, int]:
        """``(c_ij, n)``: the best increase of the path's value by inserting ``task``, and the
        last position that gives it (a tie keeps the path in bundle order)."""
        best, where = -np.inf, self.first_free
        for n in range(self.first_free, len(self.path) + 1):
            gain = path_value(self.index, (*self.path[:n], task, *self.path[n:])) - base
            if gain >= best:
                best, where = gain, n
        return best, where

    def build(self, path_value: PathValue, max_bundle: int, warp: bool) -> bool:
        """Phase 1: add tasks while the bundle has room and a task is won; whether any was.
        With ``warp``, a bid is at most the bundle's last one (module docstring)."""
        i, added = self.index, False
        while len(self.bundle) < max_bundle:
            base = path_value(i, tuple(self.path))
            cap = self.bids[self.bundle[-1]] if warp and self.bundle else np.inf
            choice: tuple[float, int, int, float] | None = None
            for j in range(self.bids.shape[0]):
                if j in self.bundle:
                    continue
                c, n = self.marginal(path_value, j, base)
                bid = min(c, cap)
                if _beats(bid, i, self.bids[j], self.winners[j]) and (
                    choice is None or c > choice[0]
                ):
                    choice = (c, j, n, bid)
            if choice is None:
                return added
            _, j, n, bid = choice
            self.bundle.append(j)
            self.path.insert(n, j)
            self.bids[j], self.winners[j] = bid, i
            added = True
        return added

    def release(self) -> None:
        """Drop the first task no longer won and every later one, resetting the later ones
        still believed won."""
        lost = next((n for n, j in enumerate(self.bundle) if self.winners[j] != self.index), None)
        if lost is None:
            return
        for j in self.bundle[lost + 1 :]:
            if self.winners[j] == self.index:
                self.bids[j], self.winners[j] = 0.0, NOBODY
        dropped = set(self.bundle[lost:])
        del self.bundle[lost:]
        self.path = [j for j in self.path if j not in dropped]


def _receive(
    me: _Agent, k: int, y_k: np.ndarray, z_k: np.ndarray, s_k: np.ndarray, s_i: np.ndarray
) -> None:
    """Apply Table I of the paper to every task of the message ``(y_k, z_k, s_k)`` from agent
    ``k`` (``s_i``: the receiver's timestamps before this round's messages)."""
    i = me.index
    y_i, z_i = me.bids, me.winners

    def newer(m: int) -> bool:  # the sender's information about agent m is newer
        return bool(s_k[m] > s_i[m])

    for j in range(y_k.shape[0]):
        zk, zi = int(z_k[j]), int(z_i[j])
        higher = _beats(y_k[j], zk, y_i[j], zi)
        update = reset = False
        if zk == k:
            if zi == i:
                update = higher
            elif zi == k or zi == NOBODY:
                update = True
            else:
                update = newer(zi) or higher
        elif zk == i:
            if zi == k:
                reset = True
            elif zi not in (i, NOBODY):
                reset = newer(zi)
        elif zk != NOBODY:  # the sender thinks a third agent m = zk wins
            if zi == i:
                update = newer(zk) and higher
            elif zi == k:
                update, reset = newer(zk), not newer(zk)
            elif zi == zk or zi == NOBODY:
                update = newer(zk)
            else:  # a fourth agent n = zi
                update = newer(zk) and (newer(zi) or higher)
                reset = not update and newer(zi) and s_i[zk] > s_k[zk]
        elif zi == k:  # the sender thinks nobody wins
            update = True
        elif zi not in (i, NOBODY):
            update = newer(zi)
        if update:
            y_i[j], z_i[j] = y_k[j], zk
        elif reset:
            y_i[j], z_i[j] = 0.0, NOBODY


def _link_matrix(
    links: Callable[[int], np.ndarray] | np.ndarray | None, n_agents: int, round_index: int
) -> np.ndarray:
    """``(m, m)`` bool: ``[i, k]`` whether agent ``i`` hears agent ``k`` in this round."""
    if links is None:
        return np.ones((n_agents, n_agents), dtype=bool)
    matrix = np.asarray(links(round_index) if callable(links) else links, dtype=bool)
    if matrix.shape != (n_agents, n_agents):
        raise ValueError(f"links must be ({n_agents}, {n_agents}), got {matrix.shape}")
    return matrix


def cbba(
    n_agents: int,
    n_tasks: int,
    path_value: PathValue,
    max_bundle: int,
    links: Callable[[int], np.ndarray] | np.ndarray | None = None,
    committed: Sequence[int | None] | None = None,
    max_rounds: int = 1000,
    warp_bids: bool = True,
) -> Allocation:
    """Allocate ``n_tasks`` tasks to ``n_agents`` agents with CBBA (module docstring).

    Args:
        n_agents: ``m``, at least 1.
        n_tasks: the tasks, numbered ``0 .. n_tasks - 1``.
        path_value: ``path_value(agent, path)``, the value of an agent flying ``path`` (a tuple
            of distinct tasks) in that order; the marginal scores are its differences.
        max_bundle: ``L_t``, the most tasks in a bundle (a committed task included), >= 1.
        links: who hears whom: ``None``, everybody every round; an ``(m, m)`` bool array
            (``[i, k]``: ``i`` hears ``k``; the diagonal is ignored), every round; or a function
            of the round (0, 1, ...) returning one, to drop messages round by round.
        committed: per agent, the task it already flies (first in its bundle and path, never
            outbid) or ``None``.
        max_rounds: stop after this many rounds, converged or not.
        warp_bids: bid at most the bundle's last bid (Johnson et al. 2012; a no-op under
            diminishing marginal gains), so that CBBA converges whatever the scores; ``False``:
            the 2009 paper's bid, the marginal score itself.

    Raises:
        ValueError: counts out of range, committed tasks out of range or shared, a bad links
            matrix.
    """
    if n_agents < 1 or n_tasks < 0 or max_bundle < 1 or max_rounds < 1:
        raise ValueError(
            f"need n_agents >= 1, n_tasks >= 0, max_bundle >= 1, max_rounds >= 1; got "
            f"{n_agents}, {n_tasks}, {max_bundle}, {max_rounds}"
        )
    commitments: list[int | None] = [None] * n_agents if committed is None else list(committed)
    held = [c for c in commitments if c is not None]
    if (
        len(commitments) != n_agents
        or len(set(held)) != len(held)
        or any(not 0 <= c < n_tasks for c in held)
    ):
        raise ValueError(
            f"committed must give {n_agents} distinct tasks in 0..{n_tasks - 1} or None, "
            f"got {committed!r}"
        )
    agents = [_Agent(i, n_agents, n_tasks) for i in range(n_agents)]
    for i, c in enumerate(commitments):
        if c is None:
            continue
        agents[i].bundle, agents[i].path, agents[i].first_free = [c], [c], 1
        for agent in agents:
            agent.bids[c], agent.winners[c] = np.inf, i
    converged, rounds = False, 0
    while rounds < max_rounds and not converged:
        heard = _link_matrix(links, n_agents, rounds)
        rounds += 1
        changed = False
        for agent in agents:
            changed |= agent.build(path_value, max_bundle, warp_bids)
        sent = [(a.bids.copy(), a.winners.copy(), a.stamps.copy()) for a in agents]
        for agent in agents:
            i = agent.index
            before = (agent.bids.copy(), agent.winners.copy(), list(agent.bundle))
            senders = [k for k in range(n_agents) if k != i and heard[i, k]]
            for k in senders:
                y_k, z_k, s_k = sent[k]
                _receive(agent, k, y_k, z_k, s_k, sent[i][2])
            stamps = sent[i][2].copy()
            for k in senders:
                stamps = np.maximum(stamps, sent[k][2])
            stamps[senders] = rounds
            stamps[i] = rounds
            agent.stamps = stamps
            agent.release()
            changed |= not (
                np.array_equal(before[0], agent.bids)
                and np.array_equal(before[1], agent.winners)
                and before[2] == agent.bundle
            )
        converged = not changed and all(
            np.array_equal(a.bids, agents[0].bids) and np.array_equal(a.winners, agents[0].winners)
            for a in agents
        )
    return _allocation(agents, commitments, path_value, n_tasks, rounds, converged)


def _allocation(
    agents: list[_Agent],
    commitments: list[int | None],
    path_value: PathValue,
    n_tasks: int,
    rounds: int,
    converged: bool,
) -> Allocation:
    """The `Allocation` of the agents' final knowledge."""
    winners = np.full(n_tasks, NOBODY, dtype=np.int64)
    bids = np.zeros(n_tasks)
    for agent in agents:  # lowest index first: a tie keeps the lower agent
        for j in agent.bundle:
            if winners[j] == NOBODY or agent.bids[j] > bids[j]:
                winners[j], bids[j] = agent.index, agent.bids[j]
    for i, c in enumerate(commitments):
        if c is not None:
            bids[c] = path_value(i, (c,)) - path_value(i, ())
    return Allocation(
        tuple(tuple(a.path) for a in agents),
        tuple(tuple(a.bundle) for a in agents),
        winners,
        bids,
        rounds,
        converged,
    )
