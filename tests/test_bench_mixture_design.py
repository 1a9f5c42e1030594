"""The regions the mixture-design benchmark averages over (training.bench.mixture_design), on synthetic renders."""

from __future__ import annotations

import numpy as np
import pytest

from training.bench import backlit, mixture_design


def test_regions_are_the_ears_and_the_shadow_band_next_to_the_lit_head():
    h, w = 20, 30
    alpha = np.zeros((h, w))
    alpha[2:18, 2:28] = 1.0  # head and ears cover this
    ears = np.zeros((h, w, 3))
    ears[2:18, 24:28] = 1.0  # the ears: columns 24-27
    diffuse = np.zeros((h, w, 3))
    diffuse[2:18, 2:12] = 0.5  # the key light lights columns 2-11 of the head; 12-23 are in its shadow
    regions = mixture_design.regions(diffuse, alpha, ears)
    assert regions["back-lit ear"].sum() == 16 * 4 and regions["back-lit ear"][2:18, 24:28].all()
    band = regions["shadow-edge bleed"]
    cols = np.flatnonzero(band.any(axis=0))
    assert cols.tolist() == list(range(12, 12 + mixture_design.EDGE_PX))  # shadowed, within EDGE_PX of the lit part
    assert not band[:, 24:].any() and not band[:2].any()  # never the ears, never the background


def test_backlit_scenes_are_named():
    with pytest.raises(ValueError, match="scene must be one of"):
        backlit.build("front_lit", 16)
