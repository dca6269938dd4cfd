"""Global planner (paper Sec. IV-C): the tree search, the interface it asks of an MDP, the
sub-task MDP it searches, rollout policies, and the hierarchical planner that flies the plan."""

from hptrack.planning.mdp import MdpKernels, register_mdp
from hptrack.planning.rollout import UniformRandom, register_policy
from hptrack.planning.search import SearchResult, search, search_mdp
from hptrack.planning.subtask_mdp import PlanningProblem
from hptrack.planning.tree import ActionStats

__all__ = [
    "ActionStats",
    "MdpKernels",
    "PlanningProblem",
    "SearchResult",
    "UniformRandom",
    "register_mdp",
    "register_policy",
    "search",
    "search_mdp",
]
