"""Mitsuba 3 vs our mixture renderer on the network's media at the dark tone R10 (in make test) and the medium one
R05 (in the opt-in ``make validate``, pytest marker ``validation``): the check of tests/mitsuba_agreement.py, in a
file of its own so that ``make test``'s two workers (whole files each) share it with the light tone's
(tests/test_mitsuba_compare.py)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.mitsuba_agreement import mitsuba_and_ours_agree  # noqa: E402


@pytest.mark.slow
@pytest.mark.parametrize("name", ["R10", pytest.param("R05", marks=pytest.mark.validation)])
def test_mitsuba_and_ours_agree_and_would_catch_a_5_percent_error(name):
    mitsuba_and_ours_agree(name)
