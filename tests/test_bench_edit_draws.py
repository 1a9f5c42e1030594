"""`python -m training.bench.edit_draws` renders a constant edit and the flush painted by a mask fed to each control
with the table's texels drawn and from a cache, and prints the bias and noise of each; it refuses counts below 1."""

from __future__ import annotations

import re

import numpy as np
import pytest

from tests.test_cli_bad_input import assert_one_line
from training.bench import edit_draws


def test_a_small_run_prints_the_bias_and_the_noise_of_both_paths(capsys):
    assert edit_draws.main(["--resolution", "24", "--long", "64", "--short", "2", "--seeds", "2"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 10
    assert lines[0].endswith("against its cache (cache input 0)")  # the constant edit read from the table
    assert lines[5].endswith("(cache input -6)")  # the fed case: Blood and Oxygenation flagged as fed
    bias = r"  bias, drawn against cached \(R, G, B\): (?:[+-]\d+\.\d\d %(?:, )?){3}"
    for first in (0, 5):
        assert re.fullmatch(bias, lines[first + 1])
        rms = [[float(v) for v in line.split(": ")[1].split(", ")] for line in lines[first + 3:first + 5]]
        assert [line.split(",")[0] for line in lines[first + 3:first + 5]] == ["  RMS error at 2 samples"] * 2
        assert all(len(r) == 2 and np.all(np.isfinite(r)) and min(r) > 0.0 for r in rms)


@pytest.mark.parametrize("argv, message", [(["--seeds", "0"], "--seeds must be at least 1, not 0"),
                                           (["--long", "-1"], "--long must be at least 1, not -1")])
def test_bad_counts_exit_2_with_one_line(argv, message, capsys):
    with pytest.raises(SystemExit) as done:
        edit_draws.main(argv)
    assert_one_line(done.value.code, capsys.readouterr().err, message)
