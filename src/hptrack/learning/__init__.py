"""Learning baselines on the Gymnasium environments (optional extra ``hptrack[learn]``).

* :mod:`~hptrack.learning.adfq`: the ADFQ posterior of a Gaussian Q-value (numpy);
* :mod:`~hptrack.learning.network`, :mod:`~hptrack.learning.replay`,
  :mod:`~hptrack.learning.agent`, :mod:`~hptrack.learning.train`: Deep ADFQ and its training
  loop (PyTorch);
* :mod:`~hptrack.learning.sb3`: PPO from stable-baselines3 trained the same way;
* :mod:`~hptrack.learning.policy_planner`: trained policies as planners (``adfq``, ``sb3``).

:mod:`~hptrack.learning.adfq`, :mod:`~hptrack.learning.curves` and
:mod:`~hptrack.learning.policy_planner` import without torch; the planners load it when they
are reset.
"""
