"""Learning baselines on the Gymnasium environments (optional extra ``hptrack[learn]``).

* `adfq`: the ADFQ posterior of a Gaussian Q-value (numpy);
* `network`, `replay`,
  `agent`, `train`: Deep ADFQ and its training
  loop (PyTorch);
* `sb3`: PPO from stable-baselines3 trained the same way;
* `policy_planner`: trained policies as planners (``adfq``, ``sb3``).

`adfq`, `curves` and
`policy_planner` import without torch; the planners load it when they
are reset.
"""
