"""RLHF / RLHF-ReS: the PPO pieces (pure functions), the fine-tuning objective, presets, and
the rewards, a user's own included (``register_reward``, docs/rlhf.md)."""

from trajpref.rl.rewards import (
    register_reward,
    registered_reward,
    registered_rewards,
    unregister_reward,
)

__all__ = ["register_reward", "registered_reward", "registered_rewards", "unregister_reward"]
