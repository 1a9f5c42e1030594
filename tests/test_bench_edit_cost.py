"""training.bench.edit_cost's paired ratio: each render against the unedited group's render of the same round."""

import statistics

from training.bench.edit_cost import paired_ratio


def test_paired_ratio_cancels_what_slows_both_renders_of_a_round():
    """Rounds whose both renders a busy machine slowed (by up to 3x) leave the paired ratio at the edit's own 1.08,
    where the ratio of the medians of all renders does not recover it."""
    anchor = [1.0, 3.0, 1.2, 2.5, 1.1, 2.8, 1.0]
    ours = [1.08 * a for a in anchor]
    ours[0] = 1.9  # one edited render slowed alone
    ratio, low, high = paired_ratio(ours, anchor)
    assert abs(ratio - 1.08) < 1e-12
    assert low <= ratio <= high and abs(low - 1.08) < 1e-12
    assert high <= 1.9 / 1.0
    assert statistics.median(ours) / statistics.median(anchor) > 1.5  # what the ratio of medians says


def test_paired_ratio_interval_spans_the_spread_of_the_rounds():
    """Rounds that disagree give an interval around their median, inside their range."""
    anchor = [1.0] * 9
    ours = [1.00, 1.02, 1.04, 1.06, 1.08, 1.10, 1.12, 1.14, 1.16]
    ratio, low, high = paired_ratio(ours, anchor)
    assert abs(ratio - 1.08) < 1e-12
    assert 1.0 <= low < ratio < high <= 1.16
