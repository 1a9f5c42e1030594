"""A dataset split built a block of wavelengths at a time (``training.data.blocks``), with the real walker."""

from dataclasses import replace

import h5py
import numpy as np
import pytest

from exporters.cli_io import output_lock
from exporters.constants import N_RADIAL_BINS, N_WAVELENGTHS
from training.commands.dataset import main as dataset_main
from training.data import store
from training.data.blocks import block_seed, build_split_blocked, wavelength_blocks
from training.data.build import build_split, split_tones
from training.data.presets import PRESETS
from training.data.reweight import TrajectoryStore
from training.data.summary import write_summary

#: 4 validation tones in blocks of 100 wavelengths (4 blocks), 2 tones per reweighting chunk.  Few photons and a
#: 2,000-step cap: these tests check the bookkeeping; the physics test below walks more.
TINY = replace(PRESETS["smoke"], n_validation=4, photons=40, walk_chunk_photons=20, walk_max_steps=2_000,
               reweighted_chunk_tones=2, wavelength_block=100)


class Interrupt(Exception):
    pass


def stores(out, preset, log=None, fail_block=None, split="validation"):
    """walk_store for build_split_blocked: the real TrajectoryStore of each block; ``log`` gets the blocks that
    reweight tones; block ``fail_block`` dies after its first chunk of tones (a kill)."""
    class Store(TrajectoryStore):
        def __call__(self, tones, photons, seed, device):
            if log is not None:
                log.append(self.block)
            if self.block == fail_block and log.count(self.block) > 1:
                raise Interrupt
            return super().__call__(tones, photons, seed, device)

    def make(b, channels, seed):
        cap = {} if preset.walk_max_steps is None else {"max_steps": preset.walk_max_steps}
        s = Store(out / f"trajectories_{split}" / f"block{b:03d}", preset.photons, seed, channels=channels,
                  chunk_photons=preset.walk_chunk_photons, **cap)
        s.block = b
        return s
    return make


def test_blocks_cover_the_wavelengths_once_with_their_own_seeds():
    blocks = wavelength_blocks(100)
    assert [b.size for b in blocks] == [100, 100, 100, 76]
    np.testing.assert_array_equal(np.concatenate(blocks), np.arange(N_WAVELENGTHS))
    assert len({block_seed(s, b) for s in (1, 2) for b in range(len(blocks))}) == 2 * len(blocks)
    with pytest.raises(ValueError, match="wavelength_block"):
        wavelength_blocks(0)


def test_blocked_split_resumes_deletes_its_walks_and_reads_as_one_file(tmp_path, monkeypatch):
    log = []
    with pytest.raises(Interrupt):
        build_split_blocked(TINY, "validation", tmp_path, stores(tmp_path, TINY, log, fail_block=1), progress=False)
    assert log == [0, 0, 1, 1]  # block 0 done (2 chunks), block 1 killed in its second chunk
    assert not list((tmp_path / "trajectories_validation" / "block000").glob("chunk*.npz"))  # block 0's walk deleted
    assert list((tmp_path / "trajectories_validation" / "block001").glob("chunk*.npz"))  # block 1's kept to resume
    assert not (tmp_path / "validation.h5").exists()

    log.clear()
    path = build_split_blocked(TINY, "validation", tmp_path, stores(tmp_path, TINY, log), progress=False)
    assert log == [1, 2, 2, 3, 3]  # resumed in block 1's second chunk; block 0 not walked again
    assert not list((tmp_path / "trajectories_validation").glob("block*/chunk*.npz"))

    tones, _ = split_tones(TINY, "validation")
    monkeypatch.chdir(tmp_path.parent)  # the joined file finds its blocks wherever the reader runs
    with h5py.File(path, "r") as f:
        assert f["profile"].shape == (4, N_WAVELENGTHS, N_RADIAL_BINS) and f["R_d"].shape == (4, N_WAVELENGTHS)
        np.testing.assert_array_equal(f["tone"][:], tones)
        r_d, profile = f["R_d"][:], f["profile"][2]
        assert np.all(np.isfinite(profile)) and np.all(np.isfinite(r_d)) and r_d.min() > 0
    # every block's columns are that block's own reweighting: walk block 2 again (same seed) and compare
    seed = split_tones(TINY, "validation")[1]
    again = stores(tmp_path / "again", TINY)(2, wavelength_blocks(100)[2], block_seed(seed, 2))
    np.testing.assert_array_equal(again(tones, TINY.photons, 0, "cpu")["R_d"].astype(np.float32), r_d[:, 200:300])
    split = store.read_split(path, ("tone", "R_d", "albedo_rgb"))
    assert split["albedo_rgb"].shape == (4, 3) and np.all(split["albedo_rgb"] > 0)
    summary = write_summary(tmp_path)["validation"]  # the deleted walks' time is kept
    assert summary["tones"] == 4 and summary["walk_s"] > 0 and summary["file_bytes"] > 4 * N_WAVELENGTHS * 8
    # run again: the joined file is there, nothing is walked
    log.clear()
    assert build_split_blocked(TINY, "validation", tmp_path, stores(tmp_path, TINY, log), progress=False) == path
    assert log == []


def test_blocked_split_agrees_with_one_walk_of_all_wavelengths(tmp_path):
    """Same estimand: the blocked split (4 independent walks) and the usual split (one walk) of the same tones
    agree within their standard errors over all wavelengths."""
    preset = replace(TINY, n_validation=2, photons=600, walk_chunk_photons=300, walk_max_steps=None,
                     reweighted_chunk_tones=2, wavelength_block=94)
    blocked = build_split_blocked(preset, "validation", tmp_path / "b", stores(tmp_path / "b", preset),
                                  progress=False)
    seed = split_tones(preset, "validation")[1]
    walk = TrajectoryStore(tmp_path / "w" / "t", preset.photons, seed, chunk_photons=300)
    whole = build_split(preset, "validation", tmp_path / "w", walk, method="reweighted", progress=False, chunk_tones=2)
    with h5py.File(blocked) as a, h5py.File(whole) as b:
        z = (a["R_d"][:] - b["R_d"][:]) / np.hypot(a["R_d_stderr"][:], b["R_d_stderr"][:])
        assert a.attrs["wavelength_block"] == 94
    assert np.all(np.isfinite(z))
    assert abs(z.mean()) < 0.15 and 0.8 < z.std() < 1.25 and np.mean(np.abs(z) > 3.5) < 0.01, (z.mean(), z.std())


def test_training_split_keeps_profiles_at_the_fitted_wavelengths(tmp_path):
    preset = replace(TINY, n_train=2, train_profile_stride=4)
    path = build_split_blocked(preset, "train", tmp_path, stores(tmp_path, preset, split="train"), progress=False)
    with h5py.File(path, "r") as f:
        kept = np.arange(0, N_WAVELENGTHS, 4)
        assert np.all(np.isfinite(f["profile"][:, kept])) and np.all(np.isfinite(f["profile_stderr"][:, kept]))
        assert np.all(np.isnan(f["profile"][:, 1::4])) and np.all(np.isfinite(f["R_d"][:]))
        store.check_profile_wavelengths(f, kept, "fit it")
        with pytest.raises(ValueError, match="every 4th wavelength only"):
            store.check_profile_wavelengths(f, np.arange(0, N_WAVELENGTHS, 2), "fit it")
    with h5py.File(tmp_path / "train.blocks" / "block000.h5", "r") as f:
        assert f["profile"].shape == (2, 25, N_RADIAL_BINS)  # what is not kept is not stored
    with pytest.raises(ValueError, match="multiple of train_profile_stride"):
        odd = replace(preset, wavelength_block=6)
        build_split_blocked(odd, "train", tmp_path / "x", stores(tmp_path / "x", odd, split="train"))


def test_shards_build_disjoint_blocks_and_the_last_joins_them(tmp_path):
    """--shard I/N: blocks I, I + N, ...; the shard that finds every block complete joins the split, the same
    file bit for bit as one process's."""
    assert build_split_blocked(TINY, "validation", tmp_path, stores(tmp_path, TINY), progress=False,
                               shard=(0, 2)) is None
    assert sorted(p.name for p in (tmp_path / "validation.blocks").glob("*.h5")) == ["block000.h5", "block002.h5"]
    path = build_split_blocked(TINY, "validation", tmp_path, stores(tmp_path, TINY), progress=False, shard=(1, 2))
    one = build_split_blocked(TINY, "validation", tmp_path / "one", stores(tmp_path / "one", TINY), progress=False)
    with h5py.File(path) as a, h5py.File(one) as b:
        for name in ("R_d", "R_d_stderr", "profile", "profile_stderr", "albedo_rgb"):
            np.testing.assert_array_equal(a[name][:], b[name][:])


def test_paper_preset_refuses_a_scheduler_and_splits_run_side_by_side(tmp_path, capsys):
    out = tmp_path / "d"
    out.mkdir()
    assert dataset_main(["--preset", "paper", "--out", str(out), "--scheduler", "local:2"]) == 2
    assert "without --scheduler" in capsys.readouterr().err
    with output_lock(out, "test", "train"):  # a process building the training split
        assert dataset_main(["--preset", "ci", "--out", str(out), "--no-progress"]) == 2  # both splits: refused
        assert "in use by process" in capsys.readouterr().err
        assert dataset_main(["--preset", "smoke", "--split", "validation", "--out", str(out), "--no-progress"]) == 0
    assert (out / "validation.h5").exists() and not (out / "train.h5").exists()
