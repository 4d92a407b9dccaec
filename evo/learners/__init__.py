"""Learners of the inner loop: PPO and the random policy (SPEC section 4)."""
