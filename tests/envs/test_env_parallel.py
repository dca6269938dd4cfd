"""``TeamParallelEnv``: the team's environment in PettingZoo's parallel API passes PettingZoo's
own API test, and its steps are the team environment's, split by UAV."""

import numpy as np
import pytest

pytest.importorskip("pettingzoo")

from pettingzoo.test import parallel_api_test  # noqa: E402

from hptrack.envs import TeamTrackingEnv  # noqa: E402
from hptrack.envs.parallel import TeamParallelEnv  # noqa: E402


@pytest.mark.parametrize("kwargs", [{}, {"team": 3, "action_type": "box", "n_targets": 2}])
def test_pettingzoos_parallel_api_test(kwargs):
    parallel_api_test(TeamParallelEnv(**kwargs), num_cycles=200)


def test_its_steps_are_the_team_environments_split_by_uav():
    parallel, team = TeamParallelEnv(team=3, n_targets=4), TeamTrackingEnv(team=3, n_targets=4)
    obs, infos = parallel.reset(seed=7)
    whole, info = team.reset(seed=7)
    assert parallel.agents == ["uav_0", "uav_1", "uav_2"]
    rng = np.random.default_rng(1)
    while parallel.agents:
        np.testing.assert_array_equal(np.concatenate([obs[a] for a in parallel.agents]), whole)
        assert all(i["U"] == info["U"] for i in infos.values())
        action = rng.integers(13, size=3)
        obs, rewards, terms, truncs, infos = parallel.step(
            {f"uav_{j}": int(a) for j, a in enumerate(action)}
        )
        whole, reward, _, truncated, info = team.step(action)
        assert set(rewards.values()) == {reward} and set(truncs.values()) == {truncated}
        assert not any(terms.values())
    assert truncated and parallel.agents == []
    with pytest.raises(ValueError, match="every UAV"):
        parallel.reset(seed=0)
        parallel.step({"uav_0": 1})
