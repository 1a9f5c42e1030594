"""The paper's ablations (§5, §8), trained and gated alike: ``python -m training ablations``."""
