"""What a `paper`-preset build costs, stage by stage, measured on small samples and scaled (``python -m training
bench --only training.bench.paper_cost``).

The `paper` preset (``training.data.presets``): 25,000 + 5,000 tones, 1.3 x 10^6 photons per wavelength at all
376 wavelengths, walked and reweighted 8 wavelengths at a time; fits at the wavelengths the model is supervised on
(every 4th: ``fit --wavelength-stride 4 --anchor-every 12``, the shipped model's, 94 wavelengths), K = 1, 2, 3,
swept along wavelength (the default), of the training tones and 1,000 validation tones.
CPU time of one thread (``time.process_time``; numba and torch on one thread), so a shared machine's load changes
the wall time, not these numbers, much.

Measured in this run, each on a sample of the real work:

* **dataset walks**: the baseline walk of the dataset's slab medium (``training.data.reweight.walk``, paths
  recorded) at every 8th wavelength, packets per CPU-s; a `paper` build walks 2 splits x 1.3e6 x 376 packets.
* **validation**: the gate's ground-truth walk (its 20 tones' baseline, every other wavelength), packets per CPU-s.
* **memory and disk**: counted from the measured size of a walk record, for the block-wise build
  (``training.data.blocks``) and for one walk of all wavelengths per split.
* **reweighting**: the CPU path of ``reweight`` (photons summed in bin order, in cache-sized tiles, by a compiled
  pass, ``training.data.binned_sums``) and, side by side on the same walk and tones, the torch path it replaces
  (one exponent product over all levels and scattered adds per channel), in CPU-ns per (tone, reflected photon,
  wavelength), for one chunk of the preset's tones (1,024) on a walk of the preset's 1.3e6 photons at 2
  wavelengths (250 and 350 nm, the cheapest to walk), once the walk's photons are sorted by bin (a process sorts a
  loaded walk once; that cost is timed apart and counted once per block); a `paper` build reweights each split's
  tones from its own walk, whose reflected photons per packet the walk sample gives.
* **fits**: ``fit_rows``'s sweep (``fit_tones_sweep``, K = 1, 2, 3, anchors every 12th fitted wavelength) of one
  chunk of 16 and one of 64 tones (``fit --chunk-tones``: the per-call overhead of the small batched steps is
  amortised over a chunk's tones) at 94 wavelengths, their profiles reweighted from a sample walk; LUT: the
  diffusion-dipole stand-in (``training.fit.problems.bench_lut``; $SKIN_SSS_LUT names the MC table, whose 2.6 GB
  are gathered from at random and may cost more).  The sample's profiles hold fewer photons than the dataset's,
  which may change the iterations the fitter takes.

Taken from the record, not measured here (each says where): the LUT, training, export and the gate's
paper-method fits.  The old
projection (``OLD_CPU_H``) is docs/research/scaling_out.md's before the compiled walker and these speed-ups.
"""

from __future__ import annotations

import time

import numpy as np
import torch

from training.data.presets import PRESETS

#: The projection before the compiled walker (docs/research/scaling_out.md), CPU-hours per stage; the fits there
#: were at all 376 wavelengths.
OLD_CPU_H = {"dataset walks": 20.0, "reweighting": 37.0, "fits": 90.0, "LUT": 0.2, "training": None,
             "export": None, "validation": 0.5}
#: Laptop rebuild, one thread (docs/research/rebuilding.md): stage 1 5 min, stage 2 30 min on one core; stage 3
#: 300 epochs on 2 threads, ~1 h 40 min wall (~3.3 CPU-h), of which ~5-10 min loading the profiles.
LAPTOP_TRAINING_CPU_H = 5 / 60 + 30 / 60 + 3.3
#: Of that, loading the training profiles (linear in the tones): ~7.5 min of the ~5-10 recorded.
LAPTOP_PROFILE_LOAD_CPU_H = 7.5 / 60
#: The `paper` build trains the laptop rebuild's optimizer steps (``train --epochs 120,200,60``: the laptop's
#: 600,1000,300 epochs over 5x the tones), each tone seen 1/5 as often: the ablation with 1/20 of the tones at
#: the same steps was 13x worse on the gate (docs/validation/ablations.md), so the model is bound by its tones,
#: not its steps.  The paper's own epochs over 25,000 tones would cost 5x (``PAPER_EPOCHS_CPU_H``).
PAPER_EPOCH_FACTOR = 5
#: The gate's paper-method fits (docs/research/rebuilding.md): 46 min wall on 2 workers (~1.5 CPU-h), the same
#: at any preset; its ground-truth walk is measured here.
VALIDATION_FITS_CPU_H = 1.5
#: The 800 x 800 LUT at 10^6 photons per node: 775 s in one process (docs/research/scaling_out.md).
LUT_CPU_H = 775 / 3600
#: Export to ONNX and the add-on's tables: seconds (docs/research/rebuilding.md).
EXPORT_CPU_H = 0.01
WAVELENGTHS = 376
FIT_STRIDE = 4
#: Validation tones fitted (``fit --split validation --max-tones 1000``): the training's validation losses and the
#: gate's Table 3 read 1,000, as many as the `laptop` split holds; the paper fits its training tones only.
VALIDATION_FITTED_TONES = 1_000


def _cpu(fn):
    t0 = time.process_time()
    out = fn()
    return time.process_time() - t0, out


def _walk_and_reweight(quick: bool) -> dict:
    from training.data import reweight as rw
    from training.data.sampling import training_tones

    photons = 600 if quick else 2_000
    channels = np.arange(0, WAVELENGTHS, 8)
    mua0 = rw.baseline_absorption()
    rw.walk(10, seed=1, mua0=mua0, channels=channels[:2])  # the compiled kernel loaded from numba's cache
    t_walk, sample = _cpu(lambda: rw.walk(photons, seed=3, mua0=mua0, channels=channels))
    # the reweighting's cost per photon, on a walk of the preset's photons per wavelength (the photons per radial
    # bin, hence the per-bin and per-channel costs, as in the build) at two of its cheapest wavelengths to walk
    traj = rw.walk(PRESETS["paper"].photons // (10 if quick else 1), seed=5, mua0=mua0, channels=np.array([0, 50]))
    tones = training_tones(PRESETS["paper"].reweighted_chunk_tones, seed=9)  # one reweighting chunk of the build
    rw.reweight(traj, tones[:2])
    traj._by_bin.clear()
    t_first, _ = _cpu(lambda: rw.reweight(traj, tones))  # includes sorting the walk's photons by bin
    t_new, new = _cpu(lambda: rw.reweight(traj, tones))  # every later chunk of a process: the order is cached
    lev = rw.level_index(tones, traj.levels_cm)
    mua_epi, mua_derm = (m.numpy()[:, traj.channels] for m in rw.absorption(tones))
    p1 = np.zeros((len(tones), traj.channels.size, rw.N_BINS + 1))
    p2 = np.zeros_like(p1)
    x = rw._exponent_rows(lev, mua_epi - traj.mua0, mua_derm - traj.mua0, traj.levels_cm.size, "cpu")
    t_old, _ = _cpu(lambda: rw._reweight_channels(traj, x, p1, p2))
    old_rd = rw.mean_stderr(p1.sum(-1), p2.sum(-1), traj.photons)[0]
    n_refl = traj.w.size
    gate = _gate_walk(600 if quick else 2_000)
    return {"photons": photons, "channels": channels.size, "walk_rate": photons * channels.size / t_walk,
            "gate_walk": gate,
            "record_bytes": traj.w.itemsize + traj.bin.itemsize + traj.path_cm[0].nbytes,
            "reflected_per_photon": sample.w.size / (photons * channels.size),
            "ns_new": t_new / (len(tones) * n_refl) * 1e9, "ns_old": t_old / (len(tones) * n_refl) * 1e9,
            "ns_sort": max(t_first - t_new, 0.0) / n_refl * 1e9,
            "rd_rel_diff": float(np.max(np.abs(new["R_d"] - old_rd) / old_rd))}


def _gate_walk(photons: int) -> dict:
    """The gate's ground-truth walk (``validate.gate.ground_truth``: the 20 gate tones' baseline, every other
    wavelength, compiled) timed on a sample of ``photons`` per wavelength: its packets per CPU-s, its wavelengths
    and photons per wavelength (``GateConfig``), and the CPU-hours of the whole walk."""
    from training.data import reweight as rw
    from training.validate.gate import GateConfig, gate_tones, validation_indices
    from training.validate.run import FULL_TONES

    tones = gate_tones(FULL_TONES).values
    gate = GateConfig(tones=FULL_TONES)
    wl = validation_indices(gate.wavelength_step)
    mua0, levels = rw.baseline_absorption(tones), np.unique(tones[:, 2])
    t, _ = _cpu(lambda: rw.walk(photons, seed=11, mua0=mua0, levels_cm=levels, channels=wl, compile=True))
    rate = photons * wl.size / t
    return {"rate": rate, "channels": wl.size, "photons": gate.gt_photons,
            "cpu_h": gate.gt_photons * wl.size / rate / 3600}


def _fits(quick: bool) -> dict:
    from exporters.constants import R_EDGES_CM, WAVELENGTHS_NM, anisotropy
    from training.data import reweight as rw
    from training.data.sampling import training_tones
    from training.fit.problems import bench_lut
    from training.fit.sweep import fit_tones_sweep

    photons = 1_000 if quick else 2_000
    chunks = (4, 16) if quick else (16, 64)
    widx = np.arange(0, WAVELENGTHS, FIT_STRIDE)
    traj = rw.walk(photons, seed=4, mua0=rw.baseline_absorption(), channels=widx)
    d = rw.reweight(traj, training_tones(max(chunks), seed=7))
    lut, lut_note = bench_lut()
    prof, R, se = (torch.tensor(d[k], dtype=torch.float64) for k in ("profile", "R_d", "profile_stderr"))
    g0 = torch.tensor(anisotropy(np.asarray(WAVELENGTHS_NM)[widx]))
    per_tone = {}
    for t in chunks:  # one chunk of t tones, as `fit --chunk-tones t` fits them
        cpu, _ = _cpu(lambda t=t: fit_tones_sweep(
            lut, prof[:t], R[:t], se[:t], torch.tensor(R_EDGES_CM), float(photons), g0, (1, 2, 3), anchor_every=12,
            wavelength_nm=np.asarray(WAVELENGTHS_NM)[widx]))
        per_tone[t] = cpu / t
    return {"per_tone": per_tone, "photons": photons, "wavelengths": widx.size, "lut": lut_note}


def _footprint_rows(paper, reflected_per_packet: float, record_bytes: int) -> list[dict]:
    """Memory of a dataset process and the build's disk, the block-wise `paper` preset against one walk of all
    wavelengths per split (counted from the measured record size, float32 arrays uncompressed: upper bounds)."""
    from exporters.constants import N_RADIAL_BINS

    gb = 1e-9
    walk_per_channel = paper.photons * reflected_per_packet * record_bytes  # bytes
    whole_walk = walk_per_channel * WAVELENGTHS
    block_walk = walk_per_channel * paper.wavelength_block
    spectra = 2 * WAVELENGTHS * 4  # R_d and its standard error per tone
    profiles = 2 * N_RADIAL_BINS * 4  # a profile and its standard errors per tone and wavelength
    train = paper.n_train * (spectra + profiles * len(range(0, WAVELENGTHS, paper.train_profile_stride)))
    validation = paper.n_validation * (spectra + profiles * WAVELENGTHS)
    full = (paper.n_train + paper.n_validation) * (spectra + profiles * WAVELENGTHS)
    machine = "this machine: 24 GB of memory, ~39 GB of free disk"
    return [
        {"workload": "`paper` build: walk records in a dataset process's memory", "ours":
         f"{block_walk * gb:.1f} GB (a block of {paper.wavelength_block} wavelengths)",
         "anchor": f"{whole_walk * gb:.0f} GB (one walk of all {WAVELENGTHS})",
         "ratio": f"{whole_walk / block_walk:.0f}x", "error": "",
         "notes": f"{record_bytes} bytes per reflected photon (measured record), {reflected_per_packet:.3f} reflected "
                  f"per packet, {paper.photons:,} photons per wavelength; {machine}"},
        {"workload": "`paper` build: disk (dataset + walks kept)", "ours":
         f"{(train + validation + 2 * block_walk) * gb:.0f} GB (training profiles every "
         f"{paper.train_profile_stride}th wavelength: {train * gb:.1f} GB; validation {validation * gb:.1f} GB; one "
         "block's walk per split)",
         "anchor": f"{(full + 2 * whole_walk) * gb:.0f} GB (all profiles {full * gb:.0f} GB, both walks kept)",
         "ratio": f"{(full + 2 * whole_walk) / (train + validation + 2 * block_walk):.1f}x", "error": "",
         "notes": f"float32 before LZF (upper bounds; the `laptop` files compress to ~70 %); {machine}"},
    ]


def benchmarks(quick: bool) -> list[dict]:
    """Rows for bench/results.md: one per stage (old and new projection side by side) and the total."""
    import numba

    threads_t, threads_n = torch.get_num_threads(), numba.get_num_threads()
    torch.set_num_threads(1)
    numba.set_num_threads(1)
    try:
        wr = _walk_and_reweight(quick)
        fit = _fits(quick)
    finally:
        torch.set_num_threads(threads_t)
        numba.set_num_threads(threads_n)
    gate = wr["gate_walk"]
    paper = PRESETS["paper"]
    tones = paper.n_train + paper.n_validation
    packets = 2 * paper.photons * WAVELENGTHS  # one walk per split
    reflected = wr["reflected_per_photon"] * paper.photons * WAVELENGTHS  # per split's walk
    new = {
        "dataset walks": packets / wr["walk_rate"] / 3600,
        "reweighting": (tones * wr["ns_new"] + 2 * wr["ns_sort"]) * reflected * 1e-9 / 3600,
        "fits": (paper.n_train + VALIDATION_FITTED_TONES) * fit["per_tone"][max(fit["per_tone"])] / 3600,
        "LUT": LUT_CPU_H,
        "training": LAPTOP_TRAINING_CPU_H + LAPTOP_PROFILE_LOAD_CPU_H * (PAPER_EPOCH_FACTOR - 1),
        "export": EXPORT_CPU_H,
        "validation": gate["cpu_h"] + VALIDATION_FITS_CPU_H,
    }
    old_rw = tones * reflected * wr["ns_old"] * 1e-9 / 3600
    how = {
        "dataset walks": (f"measured: {wr['walk_rate']:,.0f} packets per CPU-s (baseline slab medium, paths recorded, "
                          f"{wr['photons']:,} photons x {wr['channels']} wavelengths); 2 x {paper.photons:,} x 376 "
                          "packets"),
        "reweighting": (f"measured: {wr['ns_new']:.2f} CPU-ns per (tone, reflected photon, wavelength) against "
                        f"{wr['ns_old']:.2f} for the torch path on the same walk and "
                        f"{paper.reweighted_chunk_tones:,} tones (the preset's chunk; that path: "
                        f"{old_rw:.1f} CPU-h; R_d of both agree to {wr['rd_rel_diff']:.1e}); "
                        f"{wr['reflected_per_photon']:.3f} reflected photons per packet, 30,000 tones; sorting a "
                        f"walk's photons by bin, once per loaded block: {wr['ns_sort']:.0f} ns per photon"),
        "fits": ("measured: " + ", ".join(f"{v:.2f} CPU-s per tone in chunks of {t}"
                                          for t, v in fit["per_tone"].items()) +
                 f" (`fit --chunk-tones`; the projection takes the last) at {fit['wavelengths']} wavelengths (every "
                 f"{FIT_STRIDE}th, the supervised ones), K = 1, 2, 3 swept, profiles of a {fit['photons']:,}-photon "
                 f"walk; {paper.n_train:,} training + {VALIDATION_FITTED_TONES:,} validation tones; {fit['lut']} "
                 "(the laptop fits through the 2.6 GB MC table with torch lookups took 5-6 CPU-s per tone, "
                 "docs/research/fitting.md); the old row fitted all 376 wavelengths of 30,000 tones"),
        "LUT": "recorded (775 s, 800 x 800, 10^6 photons per node); not re-measured",
        "training": ("recorded laptop rebuild (~4 CPU-h: stages 1-2 35 min, stage 3 ~3.3 CPU-h) at the same optimizer "
                     "steps (`train --epochs 120,200,60`), its profile loading x 5; the paper's epochs over 25,000 "
                     f"tones: {LAPTOP_TRAINING_CPU_H * PAPER_EPOCH_FACTOR:.1f} CPU-h; not in the old table"),
        "export": "recorded: seconds",
        "validation": (f"measured: the gate's ground-truth walk at {gate['rate']:,.0f} packets per CPU-s "
                       f"({gate['photons']:,} photons x {gate['channels']} wavelengths, its 20 tones' baseline); "
                       f"recorded: its paper-method fits ~{VALIDATION_FITS_CPU_H} CPU-h (the old row counted 31 min "
                       "wall of one run)"),
    }
    rows = []
    for stage, hours in new.items():
        old = OLD_CPU_H[stage]
        rows.append({"workload": f"`paper` build: {stage}", "ours": f"{hours:.1f} CPU-h",
                     "anchor": "—" if old is None else f"{old:.1f} CPU-h (old projection)",
                     "ratio": "—" if old is None else f"{old / hours:.1f}x", "error": "", "notes": how[stage]})
    rows += _footprint_rows(paper, wr["reflected_per_photon"], wr["record_bytes"])
    total, old_total = sum(new.values()), sum(v for v in OLD_CPU_H.values() if v)
    rows.append({"workload": "`paper` build: total (dataset, fits, LUT, training, export, validation)",
                 "ours": f"{total:.0f} CPU-h ({total / 2:.0f} h wall on 2 idle cores)",
                 "anchor": f"~{old_total:.0f} CPU-h (old projection, without training and export)",
                 "ratio": f"{old_total / total:.1f}x", "error": "goal: <= 24 CPU-h",
                 "notes": "one thread per core; the stages run as `python -m training "
                          "dataset|fit|train|export|validate` (docs/research/scaling_out.md)"})
    return rows


if __name__ == "__main__":
    import sys

    for row in benchmarks(quick="--quick" in sys.argv):
        print(row)
