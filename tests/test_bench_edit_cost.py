"""`python -m training.bench.edit_cost` times chosen edit modes over a chosen number of rounds (the longer runs the
skin-edit page quotes), paired with the unedited group, and refuses unknown modes and rounds below 1."""

from __future__ import annotations

import re

import pytest

from training.bench import edit_cost


def test_modes_keep_the_unedited_anchor_first_and_the_bench_order():
    assert edit_cost.selected_modes() == edit_cost.MODES
    assert edit_cost.selected_modes(("flush_mask", "neutral")) == ("plain", "neutral", "flush_mask")
    with pytest.raises(ValueError, match="unknown edit-cost mode.*nope"):
        edit_cost.selected_modes(("nope", "tan"))


@pytest.mark.parametrize("argv, message", [(["--rounds", "0", "tan"], "--rounds must be at least 1, not 0"),
                                           (["flush", "nope"], "unknown edit-cost mode(s) nope: choose from")])
def test_bad_arguments_exit_2_with_one_line(argv, message, capsys):
    with pytest.raises(SystemExit) as done:
        edit_cost.main(argv)
    assert done.value.code == 2
    err = capsys.readouterr().err
    assert message in err and err.strip().count("\n") == 0, err


def test_one_round_of_a_masked_mode_renders_and_prints_its_ratio(capsys):
    assert edit_cost.main(["--rounds", "1", "flush_mask"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert re.fullmatch(r"unedited group: median \d+\.\d\d CPU-s per render, 1 round\(s\)", lines[0])
    assert len(lines) == 2 and re.match(r"flush_mask: \d+\.\d{3}x \(95 % interval", lines[1])
    assert float(lines[1].split()[1].rstrip("x")) > 0.0
