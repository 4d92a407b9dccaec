"""Analysis of evo runs: ablation statistics, plots and early-slope prediction (SPEC section 7)."""
