"""Pieces of the outer loop: GA operators, executors, recorders (SPEC sections 5 and 6)."""
