"""The representative and outlier tones shipped in ``tones.csv`` (figures, swatches, validation gate)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from exporters.constants import PARAM_NAMES

TONES_FILE = Path(__file__).with_name("tones.csv")


@dataclass(frozen=True)
class ToneSet:
    """Named tones: ``values`` (N, 5) in docs/contracts.md §1 order, ``names`` and ``kinds`` (N,), ``descriptions``."""

    names: tuple[str, ...]
    kinds: tuple[str, ...]
    values: np.ndarray
    descriptions: tuple[str, ...]

    def select(self, kind: str) -> ToneSet:
        """The subset of one kind: ``"representative"`` or ``"outlier"``."""
        keep = [i for i, k in enumerate(self.kinds) if k == kind]
        if not keep:
            raise ValueError(f"no tones of kind {kind!r}; kinds are {sorted(set(self.kinds))}.")
        pick = lambda seq: tuple(seq[i] for i in keep)  # noqa: E731
        return ToneSet(pick(self.names), pick(self.kinds), self.values[keep], pick(self.descriptions))


def load_tones(path: Path = TONES_FILE) -> ToneSet:
    """Read the tone table (comment lines start with ``#``)."""
    rows = [line.split(",") for line in path.read_text().splitlines() if line and not line.startswith("#")]
    header, body = rows[0], rows[1:]
    expected = ["name", "kind", *PARAM_NAMES, "description"]
    if header != expected:
        raise ValueError(f"{path}: header must be {expected}, got {header}.")
    values = np.array([[float(v) for v in row[2:7]] for row in body])
    return ToneSet(
        names=tuple(r[0] for r in body),
        kinds=tuple(r[1] for r in body),
        values=values,
        descriptions=tuple(",".join(r[7:]) for r in body),
    )
