"""evo: computational design of modular robots by evolution (structure) and PPO (behaviour)."""
