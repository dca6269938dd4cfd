"""Global planner: the sub-task MDP and its Monte Carlo tree search (paper Sec. IV-C)."""

from hptrack.planning.mcts import ActionStats, SearchResult, search
from hptrack.planning.mdp import PlanningProblem

__all__ = ["ActionStats", "PlanningProblem", "SearchResult", "search"]
