"""The dataset's reweighted estimator against direct absorbing runs of the same tones (real simulator).

One baseline walk (all 16 epidermis levels) serves every tone; each tone is also simulated directly.
The wavelengths are a subset (every 4th) to keep the test short; the estimator is the same at all 376.
"""

import json

import numpy as np
import pytest

from exporters.colorimetry import xyz_weights
from training.data.reweight import (
    WALK_CHUNK_PHOTONS,
    WALK_CHUNK_PHOTONS_CUDA,
    Trajectories,
    TrajectoryStore,
    baseline_absorption,
    one_tone,
    reweight,
    walk,
)
from training.data.sampling import T_EPI_LEVELS_CM
from training.sim.tissue import skin_medium
from training.sim.transport import simulate

CHANNELS = np.arange(0, 376, 4)
#: The store tests check bookkeeping, not physics: packets capped at 2,000 steps (the default 100,000 lets a few
#: NIR packets wander in the bloodless dermis for most of the test's time).
CAP = 2_000
PHYSICS_CAP = 20_000
PHOTONS = 400
L = T_EPI_LEVELS_CM
TONES = np.array([
    [0.02, 0.03, L[4], 0.8, 0.7],  # light, typical
    [0.20, 0.08, L[9], 0.7, 0.5],  # medium
    [0.65, 0.25, L[15], 0.5, 1.0],  # extreme: darkest, thickest, most blood (largest reweighting)
    [0.001, 0.001, L[0], 1.0, 0.0],  # extreme: lightest, thinnest (the baseline itself, long paths)
    [0.65, 0.001, L[0], 1.0, 0.0],  # extreme: thin pheomelanin-dark epidermis over bloodless dermis
])


@pytest.fixture(scope="module")
def both():
    # a cap of 20,000 steps truncates none of this walk's packets (asserted) and saves a third of its time
    traj = walk(PHOTONS, seed=13, mua0=baseline_absorption(), channels=CHANNELS, max_steps=PHYSICS_CAP)
    assert not np.any(traj.truncated)
    rw = reweight(traj, TONES)
    direct = [simulate(skin_medium(t).select_channels(CHANNELS), PHOTONS, seed=100 + i, max_steps=PHYSICS_CAP)
              for i, t in enumerate(TONES)]
    return traj, rw, direct


def test_reweighted_equals_direct_within_standard_errors(both):
    _, rw, direct = both
    for i, d in enumerate(direct):
        sigma = np.hypot(rw["R_d_stderr"][i], d.R_d_stderr)
        diff = rw["R_d"][i] - d.R_d
        assert np.all(np.abs(diff) <= 4 * sigma + 1e-4), (TONES[i], np.abs(diff / sigma).max())
        z = diff[sigma > 0] / sigma[sigma > 0]
        assert abs(z.mean()) < 0.45 and 0.7 < z.std() < 1.35, (TONES[i], z.mean(), z.std())
        # the shared walk is not much noisier than a walk of the tone itself, even at the extremes
        assert np.median(rw["R_d_stderr"][i] / np.maximum(d.R_d_stderr, 1e-12)) < 1.6
        # the radial profile agrees too (first 3 mm, where both have photons), bin sums of 32 bins
        sig_p = np.hypot(_coarse(rw["profile_stderr"][i], True), _coarse(d.profile_stderr, True))
        assert np.all(np.abs(_coarse(rw["profile"][i]) - _coarse(d.profile)) <= 5 * sig_p + 2e-4)


def _coarse(profile: np.ndarray, stderr: bool = False) -> np.ndarray:
    """Power in 13 groups of 32 radial bins (to 3 mm), (C, 13); stderr: combine bin errors in quadrature."""
    from exporters.constants import R_EDGES_CM

    power = (profile * np.pi * np.diff(R_EDGES_CM**2))[:, :416].reshape(len(CHANNELS), 13, 32)
    return np.sqrt((power**2).sum(-1)) if stderr else power.sum(-1)


def test_colour_agrees_within_its_standard_error(both):
    """XYZ under D65 (on the test's wavelength subset, weights rescaled) agrees within 4 sigma."""
    _, rw, direct = both
    w = xyz_weights("D65")[:, CHANNELS] * 4  # 8 nm steps instead of 2 nm
    for i, d in enumerate(direct):
        diff = w @ (rw["R_d"][i] - d.R_d)
        sigma = np.sqrt((w**2) @ (rw["R_d_stderr"][i] ** 2 + d.R_d_stderr**2))
        assert np.all(np.abs(diff) < 4 * sigma), (TONES[i], diff / sigma)


def test_outputs_are_finite_and_energy_is_bounded(both):
    traj, rw, _ = both
    for key, v in rw.items():
        assert np.all(np.isfinite(v)) and np.all(v >= 0), key
    assert np.all(rw["R_d"] < 1)
    assert np.all(traj.truncated == 0)
    assert np.all(traj.w <= 1) and np.all(traj.path_cm >= 0)  # baseline weights only ever shrink


def test_tones_must_be_on_a_level_and_above_the_baseline(both):
    traj, _, _ = both
    with pytest.raises(ValueError, match="not one of the walked levels"):
        reweight(traj, np.array([[0.1, 0.05, 0.0123, 0.8, 0.5]]))
    below = Trajectories(**{**traj.__dict__, "mua0": traj.mua0 * 1e3})
    with pytest.raises(ValueError, match="absorbs less than the walk's baseline"):
        reweight(below, TONES[:1])


def test_store_resumes_chunks_and_refuses_other_walks(tmp_path):
    """The dataset's on-disk walk: chunks survive a restart, another photon count is refused."""
    st = TrajectoryStore(tmp_path / "t", photons=6, seed=3, chunk_photons=4, max_steps=CAP)
    traj = st.trajectories()
    assert traj.photons == 6 and sorted(p.name for p in (tmp_path / "t").glob("chunk*.npz")) == [
        "chunk0000.npz", "chunk0001.npz"]
    (tmp_path / "t" / "chunk0001.npz").unlink()  # as if killed while walking the second chunk
    again = TrajectoryStore(tmp_path / "t", photons=6, seed=3, chunk_photons=4, max_steps=CAP).trajectories()
    for key in ("offsets", "w", "bin", "path_cm"):
        np.testing.assert_array_equal(getattr(traj, key), getattr(again, key))
    with pytest.raises(ValueError, match="other photons"):
        TrajectoryStore(tmp_path / "t", photons=7, seed=3, chunk_photons=4, max_steps=CAP).trajectories()


def test_a_gpu_walks_big_chunks_and_does_not_mix_with_a_cpu_walk(tmp_path):
    """On CUDA a chunk is a whole laptop split (the walker's time there is its step count, not its packets);
    a folder walked on a CPU is not continued in GPU-sized chunks (other seeds per chunk): named, refused."""
    cpu = TrajectoryStore(tmp_path / "t", photons=6, seed=3, max_steps=CAP)
    gpu = TrajectoryStore(tmp_path / "t", photons=6, seed=3, device="cuda", max_steps=CAP)
    assert (cpu.chunk, gpu.chunk) == (WALK_CHUNK_PHOTONS, WALK_CHUNK_PHOTONS_CUDA) == (5_000, 165_000)
    assert TrajectoryStore(tmp_path / "u", photons=6, seed=3, device="cuda", chunk_photons=4).chunk == 4
    cpu.folder.mkdir()
    cpu._check_manifest()
    with pytest.raises(ValueError, match="other chunk_photons"):
        gpu._check_manifest()


def test_store_grows_by_whole_chunks_like_a_fresh_walk(tmp_path):
    """A walk of whole chunks grows (more photons) and shrinks to a prefix; the result is a fresh walk's."""
    small = TrajectoryStore(tmp_path / "t", photons=8, seed=3, chunk_photons=4, max_steps=CAP).trajectories()
    grown = TrajectoryStore(tmp_path / "t", photons=12, seed=3, chunk_photons=4, max_steps=CAP).trajectories()
    fresh = TrajectoryStore(tmp_path / "f", photons=12, seed=3, chunk_photons=4, max_steps=CAP).trajectories()
    prefix = TrajectoryStore(tmp_path / "t", photons=8, seed=3, chunk_photons=4, max_steps=CAP).trajectories()
    assert grown.photons == 12 and prefix.photons == 8
    for key in ("offsets", "w", "bin", "path_cm", "truncated"):
        np.testing.assert_array_equal(getattr(grown, key), getattr(fresh, key))
        np.testing.assert_array_equal(getattr(prefix, key), getattr(small, key))
    assert json.loads((tmp_path / "t" / "manifest.json").read_text())["photons"] == 12


def test_a_walk_at_the_tones_own_absorption_reweights_to_its_direct_walk():
    """``walk_mua``: walked at the tone's own absorption of each layer, records kept at the baseline: the same
    seed gives the direct walk's photons, so reweighted and direct agree to float32 rounding (the
    ``simulate --method reweighted`` path); walk_mua below the baseline is refused."""
    tone = TONES[1]
    rew = one_tone(tone, 60, seed=7)
    direct = simulate(skin_medium(tone), 60, seed=7)
    np.testing.assert_allclose(rew["R_d"][0], direct.R_d, rtol=1e-5, atol=1e-9)
    np.testing.assert_allclose(rew["R_d_stderr"][0], direct.R_d_stderr, rtol=1e-4, atol=1e-9)
    np.testing.assert_allclose(rew["profile"][0], direct.profile, rtol=1e-4, atol=1e-6)
    mua0 = baseline_absorption()
    with pytest.raises(ValueError, match="walk_mua"):
        walk(2, seed=1, mua0=mua0, levels_cm=tone[2:3], walk_mua=np.stack([mua0, mua0 - 1.0]))


def test_reweighted_bin_sums_match_numpys_exponential():
    """The compiled per-bin sums (float32 exponential, float64 sums) against numpy's float64 exp and sums of the
    same exponents, over the range the reweighting meets (weights from 1 down to below float32's normals, held at
    e^EXP_MIN); no weight is a float32 denormal."""
    from training.data.binned_sums import EXP_MIN, _weights, reweighted_bin_sums

    rng = np.random.default_rng(5)
    n, n_lev, nb = 5_000, 4, 7
    cum = np.cumsum(rng.exponential(0.01, (n_lev + 1, n)), axis=0).astype(np.float32)  # cm
    log_w = np.log(rng.uniform(1e-4, 1.0, n)).astype(np.float32)
    starts = np.r_[0, np.sort(rng.choice(np.arange(1, n), nb - 1, replace=False)), n].astype(np.int64)
    level = np.array([0, 3, 1, 2])
    a = np.array([-50.0, -2.0, 0.0, -900.0])  # the last tone's weights span e^0 .. far below e^EXP_MIN
    b = np.array([-10.0, -1.0, 0.0, -400.0])
    s1, s2 = np.zeros((4, nb)), np.zeros((4, nb))
    reweighted_bin_sums(cum, log_w, level, a, b, starts, s1, s2)
    e = a[:, None] * cum[level].astype(np.float64) + b[:, None] * cum[-1].astype(np.float64) + log_w
    w = np.exp(np.maximum(e, EXP_MIN))
    ref1 = np.stack([np.add.reduceat(row, starts[:-1]) for row in w])
    ref2 = np.stack([np.add.reduceat(row * row, starts[:-1]) for row in w])
    np.testing.assert_allclose(s1, ref1, rtol=1e-6, atol=1e-37)
    np.testing.assert_allclose(s2, ref2, rtol=2e-6, atol=1e-70)
    assert np.all(np.isfinite(s1)) and np.all(np.isfinite(s2))
    held = np.empty(n, np.float32)
    _weights(cum[level[3]], cum[-1], log_w, a[3], b[3], np.empty(n, np.int32), held)
    assert held.min() >= np.finfo(np.float32).tiny  # weights held at e^EXP_MIN stay normal numbers
