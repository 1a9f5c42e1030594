"""The dataset: sampling, resumable chunked storage, shards and merge — with the real simulator (tiny photon counts)."""

from dataclasses import replace
from functools import partial

import h5py
import numpy as np
import pytest

from exporters.constants import PARAM_RANGES
from training.commands.dataset import main as dataset_main
from training.data import store
from training.data.build import build_split, merge
from training.data.presets import PRESETS
from training.data.reweight import TrajectoryStore
from training.data.sampling import T_EPI_LEVELS_CM, training_tones, validation_tones
from training.data.simulate import simulate_direct as simulate_uncapped
from training.data.summary import write_summary

#: The storage tests check bookkeeping (chunks, shards, resume), not physics: packets are capped at 2,000 steps
#: (the walker's default 100,000 lets a few NIR packets in the bloodless dermis wander for most of a test's time).
TINY = replace(PRESETS["ci"], name="ci", n_train=3, n_validation=2, photons=20, chunk_tones=1, walk_max_steps=2_000)
simulate_direct = partial(simulate_uncapped, max_steps=TINY.walk_max_steps)


def test_sampling_covers_the_ranges_and_quantises_thickness():
    train, val = training_tones(512, seed=1), validation_tones(512, seed=2)
    for tones in (train, val):
        for i, (low, high) in enumerate(PARAM_RANGES.values()):
            assert tones[:, i].min() >= low - 1e-12 and tones[:, i].max() <= high + 1e-12
        assert set(np.unique(tones[:, 2])) <= set(T_EPI_LEVELS_CM)
    # Halton stratifies: each decile of so2 and b_mel (uniform in both parts of the mixture) holds ~10 %
    for i in (3, 4):
        low, high = list(PARAM_RANGES.values())[i]
        counts = np.histogram(train[:, i], bins=10, range=(low, high))[0]
        assert counts.min() >= 45 and counts.max() <= 58, counts
    for tones in (train, val):
        # the whole box stays covered: the fractions reach both ends of their range, on a log scale
        for i in (0, 1):
            low, high = list(PARAM_RANGES.values())[i]
            x = np.log(tones[:, i] / low) / np.log(high / low)
            assert x.min() < 0.02 and x.max() > 0.95
            counts = np.histogram(x, bins=5, range=(0, 1))[0]
            assert counts.min() > 0.08 * len(tones), counts
        # a quarter of the tones come from the skin core (f_mel <= 0.2): with those from the box below 0.2,
        # 0.25 + 0.75 * P(box f_mel <= 0.2) = 0.25 + 0.75 * ln(200) / ln(650)
        expected = 0.25 + 0.75 * np.log(0.2 / 0.001) / np.log(0.65 / 0.001)
        assert abs(np.mean(tones[:, 0] <= 0.2) - expected) < 0.05
    assert not np.allclose(train[:8], val[:8])
    np.testing.assert_array_equal(training_tones(16, seed=1), train[:16])  # deterministic


class Interrupt(Exception):
    pass


def test_resume_after_a_kill_loses_at_most_one_chunk(tmp_path):
    calls = []

    def dies_after_two_chunks(tones, photons, seed, device):
        calls.append(seed)
        if len(calls) == 3:
            raise Interrupt  # the process is killed while simulating the third chunk
        return simulate_direct(tones, photons, seed, device)

    with pytest.raises(Interrupt):
        build_split(TINY, "train", tmp_path, dies_after_two_chunks, method="direct", progress=False)
    path = tmp_path / "train.h5"
    assert store.pending(path).tolist() == [2]
    calls.clear()
    build_split(TINY, "train", tmp_path, dies_after_two_chunks, method="direct", progress=False)
    assert len(calls) == 1 and store.pending(path).size == 0
    data = store.read_split(path, ("tone", "R_d", "R_d_stderr", "albedo_rgb"))
    # 20 photons per wavelength: a UV wavelength of a dark tone may see no photon come back
    assert np.all(np.isfinite(data["R_d"])) and np.all((data["R_d"] >= 0) & (data["R_d"] < 1))
    assert np.all(data["R_d"].mean(axis=1) > 0.01)
    assert np.all(data["albedo_rgb"] > 0)
    with h5py.File(path) as f:
        profile, edges = f["profile"][0], f["r_edges_cm"][:]
    area = np.pi * np.diff(edges**2)
    # the stored profile integrates to the stored R_d (what leaves beyond 5 cm is negligible here)
    np.testing.assert_allclose(profile @ area, data["R_d"][0], rtol=1e-3, atol=1e-4)


def test_shards_merge_into_the_unsharded_dataset(tmp_path):
    whole = build_split(TINY, "validation", tmp_path / "whole", simulate_direct, method="direct", progress=False)
    for i in range(2):
        build_split(TINY, "validation", tmp_path / "sharded", simulate_direct, method="direct",
                    shard=(i, 2), progress=False)
    merged = merge(tmp_path / "sharded", "validation")
    a = store.read_split(whole, ("tone", "R_d", "profile"))
    b = store.read_split(merged, ("tone", "R_d", "profile"))
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
    shard_s = [h5py.File(tmp_path / "sharded" / f"validation.shard{i}of2.h5", "r").attrs["seconds"] for i in range(2)]
    with h5py.File(merged, "r") as f:  # the merged file records the simulation time of every shard
        assert f.attrs["seconds"] == pytest.approx(sum(shard_s)) and min(shard_s) > 0
    with pytest.raises(ValueError, match="exists already"):
        merge(tmp_path / "sharded", "validation")


def test_refuses_to_mix_runs_in_one_folder(tmp_path, capsys):
    build_split(TINY, "validation", tmp_path, simulate_direct, method="direct", progress=False)
    other = replace(TINY, photons=21)
    with pytest.raises(ValueError, match="photons"):
        build_split(other, "validation", tmp_path, simulate_direct, method="direct", progress=False)
    assert dataset_main(["--out", str(tmp_path), "--shard", "3/2"]) == 2  # argparse: one line, exit status 2
    assert "--shard" in capsys.readouterr().err
    assert dataset_main(["--out", str(tmp_path), "--split", "validation", "--method", "direct", "--preset", "ci"]) == 2
    assert "photons" in capsys.readouterr().err  # the folder holds TINY's run, not ci's: refused, nothing lost
    assert store.pending(tmp_path / "validation.h5").size == 0


def test_reweighted_build_shards_and_merge(tmp_path):
    """The default estimator: shards share the split's walk and merge into the unsharded result."""
    def make(folder, shard):
        walk = TrajectoryStore(folder / "trajectories_validation", TINY.photons, TINY.validation_seed, shard=shard,
                               max_steps=TINY.walk_max_steps)
        return build_split(TINY, "validation", folder, walk, method="reweighted", shard=shard, progress=False)

    whole = make(tmp_path / "whole", (0, 1))
    for i in range(2):
        make(tmp_path / "sharded", (i, 2))
    merged = merge(tmp_path / "sharded", "validation")
    a = store.read_split(whole, ("tone", "R_d", "R_d_stderr", "profile", "profile_stderr", "albedo_rgb"))
    b = store.read_split(merged, tuple(a))
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
    assert np.all(a["R_d"].mean(axis=1) > 0.01) and np.all(np.isfinite(a["profile_stderr"]))
    with h5py.File(merged) as f:
        assert f.attrs["method"] == "reweighted"
    summary = write_summary(tmp_path / "whole")
    assert summary["validation"]["tones"] == TINY.n_validation and summary["validation"]["walk_s"] > 0
    assert (tmp_path / "whole" / "summary.png").stat().st_size > 10_000
