"""RLHF / RLHF-ReS: the PPO pieces (pure functions), the fine-tuning objective, presets."""
