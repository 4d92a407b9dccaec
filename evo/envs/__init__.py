"""Simulation environments: the reach-the-target task (SPEC section 3)."""
