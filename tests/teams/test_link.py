"""The team's link: claims heard at once, at shares only, or lost."""

import numpy as np

from hptrack.teams.link import NO_CLAIM, Link


def test_the_perfect_link_hears_a_claim_at_once():
    link = Link(3, 0.5, 0.0, 0.0, np.random.default_rng(0))
    link.claim(0, 4)
    assert link.claimed(1, 6).tolist() == [False, False, False, False, True, False]
    assert not link.claimed(0, 6).any()  # its own claim is not another's


def test_a_limited_link_hears_claims_at_its_shares_only():
    link = Link(2, 0.5, 2.0, 0.0, np.random.default_rng(0))  # a share every 4 steps
    link.claim(0, 1)
    for step in (1, 2, 3):
        link.share(step)
        assert not link.claimed(1, 3).any()
    link.share(4)
    assert link.claimed(1, 3).tolist() == [False, True, False]
    link.claim(0, NO_CLAIM)
    link.share(5)
    assert link.claimed(1, 3)[1]  # still the last heard
    assert link.info() == {"messages": 2, "lost": 0}


def test_lost_messages_follow_the_generator():
    link = Link(2, 0.5, 0.5, 0.5, np.random.default_rng(3))
    link.claim(0, 0)
    link.claim(1, 1)
    draws = np.random.default_rng(3).random(2 * 40)
    for step in range(1, 41):
        link.share(step)
    assert link.info() == {"messages": 80, "lost": int(np.sum(draws < 0.5))}
