"""Frozen staged training of the chained decoder (paper §5.2): ``python -m training train``."""
