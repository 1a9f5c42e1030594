"""``python -m training dataset``: build (or merge) the skin-tone dataset.

  python -m training dataset --preset ci|laptop|paper --out DIR [--shard I/N] [--split train|validation|both]
  python -m training dataset --merge --out DIR        # after every shard I/N has finished
  python -m training dataset --summary --out DIR      # counts, times, sizes -> summary.json, summary.png

Killing the job loses at most the chunk in flight: run the same command again to resume.  N machines
(or N processes) each run one ``--shard I/N``; ``--merge`` checks the shards and joins them.  Or
``--scheduler local:N | tcp://HOST:PORT | slurm[:JOBS]`` (``training.cluster``): the walk chunks, then the
reweighting chunks, as Dask tasks; the same files as one process (no merge), resumed the same way.

--method reweighted (default): one baseline walk per split (saved in DIR/trajectories_<split>/, in
photon chunks, shared by the shards of a split) reweighted for every tone; --method direct: one full
Monte Carlo run per tone (slow; for checks).

The `paper` preset builds a split 8 wavelengths at a time (its whole walk would not fit in memory or on disk):
each block walked, reweighted into DIR/<split>.blocks/ and its walk deleted; DIR/<split>.h5 then joins the
blocks (keep the .blocks folder beside it).  Run one process per split (--split train, --split validation) or
per share of the blocks (--shard I/N: blocks I, I + N, ...); no --scheduler.
"""

from __future__ import annotations

import argparse
import contextlib
import json
from pathlib import Path

from exporters.cli_io import OneLineParser
from training.cluster import engine
from training.commands.options import (
    check_cuda,
    check_input,
    check_output_folder,
    command,
    count,
    error_status,
    output_lock,
    parse_shard,
    shard_part,
    torch_device,
)
from training.data.build import SPLITS, build_split, merge
from training.data.presets import PRESETS


def _walk_options(preset) -> dict:
    """The TrajectoryStore options that ``preset`` sets (walk chunk and cap; the store's defaults elsewhere)."""
    return {k: v for k, v in (("chunk_photons", preset.walk_chunk_photons), ("max_steps", preset.walk_max_steps))
            if v is not None}


def _estimator(args: argparse.Namespace, preset, split: str):
    """The SimulateFn of ``args.method`` for ``split`` and its chunk size (tones written at once)."""
    if args.method == "direct":
        from training.data.simulate import simulate_direct

        return simulate_direct, preset.chunk_tones
    from training.data.build import split_tones
    from training.data.reweight import TrajectoryStore

    seed = split_tones(preset, split)[1]
    store = TrajectoryStore(args.out / f"trajectories_{split}", preset.photons, seed, device=args.device,
                            shard=args.shard, progress=not args.no_progress, **_walk_options(preset))
    return store, preset.reweighted_chunk_tones


def _build_blocked(args: argparse.Namespace, preset, splits: tuple[str, ...]) -> int:
    """Build ``splits`` a block of wavelengths at a time (``training.data.blocks``), one process per split."""
    from training.data.blocks import build_split_blocked
    from training.data.reweight import TrajectoryStore

    walk = _walk_options(preset)
    for split in splits:
        def store(b, channels, seed, split=split):
            return TrajectoryStore(args.out / f"trajectories_{split}" / f"block{b:03d}", preset.photons, seed,
                                   device=args.device, progress=not args.no_progress, channels=channels, **walk)

        path = build_split_blocked(preset, split, args.out, store, device=args.device, progress=not args.no_progress,
                                   shard=args.shard)
        print(path or f"{split}: this shard's blocks are done; the split is joined when the other shards' are")
    return 0


@contextlib.contextmanager
def _locks(out: Path, split: str, shard: tuple[int, int]):
    """Hold --out's locks: one per split written (the processes of --split train and --split validation write
    disjoint files and run together), and the whole folder's for both splits at once (the lock a second run of
    the same command meets first)."""
    part = shard_part(shard)
    parts = ([part] + [f"{s}{'-' + part if part else ''}" for s in SPLITS] if split == "both"
             else [f"{split}{'-' + part if part else ''}"])
    with contextlib.ExitStack() as stack:
        for p in parts:
            stack.enter_context(output_lock(out, "--out", p))
        yield


def _check_paths(args: argparse.Namespace) -> None:
    """InputError for an --out that cannot be the dataset folder or holds a truncated HDF5 file."""
    if args.summary or args.merge:
        check_input(args.out, "--out", "folder")
    else:
        check_output_folder(args.out, "--out")
    if args.out.is_dir():
        for path in sorted(args.out.glob("*.h5")):
            check_input(path, "dataset file", "h5")


def build_parser() -> argparse.ArgumentParser:
    """The command's argument parser (the CLI reference of the documentation reads it too)."""
    parser = OneLineParser(prog="python -m training dataset", description=__doc__.splitlines()[0],
                           formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    parser.add_argument("--preset", choices=sorted(PRESETS), default="ci")
    parser.add_argument("--out", type=Path, required=True, help="dataset folder")
    parser.add_argument("--shard", type=parse_shard, default=(0, 1), help="I/N: this process's share")
    parser.add_argument("--split", choices=[*SPLITS, "both"], default="both")
    parser.add_argument("--method", choices=["direct", "reweighted"], default="reweighted",
                        help="estimator (default reweighted; direct is a full run per tone)")
    parser.add_argument("--merge", action="store_true", help="join finished shards in --out")
    parser.add_argument("--summary", action="store_true",
                        help="write --out/summary.json and summary.png for a built dataset")
    parser.add_argument("--seed", type=int, default=None, help="override the preset's sampling seeds")
    parser.add_argument("--device", type=torch_device, default="cpu", help="cpu, cuda or cuda:N")
    parser.add_argument("--threads", type=count, default=1,
                        help="torch CPU threads (reweighting); the walk's compiled kernel runs on every CPU the "
                        "process may use (taskset or NUMBA_NUM_THREADS limit it; cluster workers walk on --threads)")
    parser.add_argument("--no-progress", action="store_true")
    engine.add_option(parser)
    return parser


@command("dataset")
def main(argv: list[str]) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    _check_paths(args)
    import torch

    torch.set_num_threads(max(1, args.threads))
    splits = SPLITS if args.split == "both" else (args.split,)
    try:
        if args.summary:
            from training.data.summary import write_summary

            print(json.dumps(write_summary(args.out), indent=1))
            return 0
        if args.merge:
            for split in splits:
                print(merge(args.out, split))
            return 0
        check_cuda(args.device)
        preset = PRESETS[args.preset]
        if args.seed is not None:
            from dataclasses import replace

            preset = replace(preset, train_seed=args.seed, validation_seed=args.seed + 1)
        blocked = preset.wavelength_block is not None and args.method == "reweighted"
        if blocked and args.scheduler is not None:
            raise ValueError(f"the {preset.name!r} preset builds a split a block of wavelengths at a time, without "
                             "--scheduler: run one process per split (--split train, --split validation) or per "
                             "share of the blocks (--shard I/N)")
        if args.scheduler is not None:
            if args.shard != (0, 1):
                raise ValueError("--shard and --scheduler exclude each other: the cluster takes every chunk")
            args.out = args.out.resolve()  # the workers write the walk chunks there
        args.out.mkdir(parents=True, exist_ok=True)
        with _locks(args.out, args.split, args.shard), \
                engine.job(args.scheduler, f"dataset {args.preset}", shared=[args.out], threads=max(1, args.threads),
                           progress=not args.no_progress) as job:
            if blocked:
                return _build_blocked(args, preset, splits)
            paths = []
            for split in splits:
                simulate, chunk = _estimator(args, preset, split)
                paths.append(build_split(preset, split, args.out, simulate, method=args.method, shard=args.shard,
                                         device=args.device, progress=not args.no_progress, chunk_tones=chunk,
                                         job=job))
                if job is None:
                    print(paths[-1])
            if job is not None:
                job.wait()
                print("\n".join(map(str, paths)))
    except (ValueError, engine.TaskError) as exc:
        return error_status(exc)
    return 0
