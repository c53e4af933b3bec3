"""Fixtures of the fine-tuning tests: no test leaves a reward registered for the next."""

import pytest

from trajpref.rl import registered_rewards, unregister_reward


@pytest.fixture(autouse=True)
def no_reward_left_registered():
    """Fails a test that leaves a reward registered (after taking it back, so that one leak
    does not fail the tests after it): register in a ``with registered_reward(...)`` block."""
    assert registered_rewards() == (), "a reward was registered before the test"
    yield
    leaked = registered_rewards()
    for name in leaked:
        unregister_reward(name)
    assert leaked == (), f"the test left rewards registered: {leaked}"
