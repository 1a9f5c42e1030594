"""``python -m training lut``: the homogeneous semi-infinite lookup tables (docs/contracts.md §2, paper §4.2).

Example (small)::

    python -m training lut --albedo-n 64 --g-n 8 --photons 20000 --out runs/lut_small.npz

Resumable: simulated g nodes are kept in ``<out>.parts/``; rerun the same command after a kill.  By
default min(g-n, 48) g nodes are simulated and the other columns interpolated along g (monotone cubic);
``--g-nodes`` sets the number.  ``--shard I/N`` splits the nodes between N processes (2 on 2 cores)::

    python -m training lut --albedo-n 800 --g-n 800 --photons 1000000 --out lut.npz --shard 0/2 &
    python -m training lut --albedo-n 800 --g-n 800 --photons 1000000 --out lut.npz --shard 1/2

or, with Dask (``training.cluster``; one task per batch of g nodes, the same files)::

    python -m training lut --albedo-n 800 --g-n 800 --photons 1000000 --out lut.npz --scheduler local:2
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from exporters.cli_io import OneLineParser
from training.cluster import engine
from training.commands.options import (
    check_output_file,
    command,
    count,
    error_status,
    fraction,
    in_range,
    output_lock,
    parse_shard,
    require,
    shard_part,
)
from training.sim.lut import ALBEDO_MAX, ALBEDO_MIN, G_MAX, G_MIN, G_NODES, MAX_STEPS, build_lut


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(
        prog="python -m training lut",
        description="R(albedo, g) and P(r | albedo, g) of a semi-infinite medium at sigma_t = 1, n = 1.4, "
        "diffuse illumination, by absorption reweighting of one non-absorbing run per simulated g.",
    )
    p.add_argument("--albedo-n", type=count, required=True, help="albedo samples (1 - albedo log-spaced)")
    p.add_argument("--g-n", type=count, required=True, help="anisotropy samples (linear)")
    p.add_argument("--photons", type=count, required=True, help="photons per simulated g node")
    p.add_argument("--g-nodes", type=count, default=None,
                   help=f"simulated g values (default min(g-n, {G_NODES})); the rest is interpolated along g")
    p.add_argument("--shard", type=parse_shard, default=(0, 1), help="I/N: this process's share of the g nodes")
    p.add_argument("--out", required=True, help="output .npz")
    p.add_argument("--albedo-min", type=fraction, default=ALBEDO_MIN)
    p.add_argument("--albedo-max", type=fraction, default=ALBEDO_MAX)
    p.add_argument("--g-min", type=in_range(-0.99, 0.99), default=G_MIN)
    p.add_argument("--g-max", type=in_range(-0.99, 0.99), default=G_MAX)
    p.add_argument("--max-steps", type=count, default=MAX_STEPS, help="walk cap per photon")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    p.add_argument("--compile", choices=("auto", "on", "off"), default="auto",
                   help="torch.compile the walker step (auto: when photons x g-n > 4M)")
    p.add_argument("--threads", type=count, default=1, help="torch CPU threads (the walker is fastest on 1)")
    p.add_argument("--no-progress", action="store_true")
    engine.add_option(p)
    return p


@command("lut")
def main(argv: list[str]) -> int:
    """Run the command; returns the exit status (2 for bad input)."""
    args = build_parser().parse_args(argv)
    require(args.albedo_min < args.albedo_max, "--albedo-min must be below --albedo-max")
    require(args.g_min < args.g_max, "--g-min must be below --g-max")
    require(args.g_nodes is None or args.g_nodes <= args.g_n, "--g-nodes must be <= --g-n")
    check_output_file(args.out, "--out", suffixes=(".npz",))
    import torch

    torch.set_num_threads(max(1, args.threads))
    compile_ = {"on": True, "off": False, "auto": args.photons * args.g_n > (1 << 22)}[args.compile]
    try:
        if args.device == "cuda" and args.scheduler is None:  # on a cluster, the workers' GPUs count
            if not torch.cuda.is_available():
                raise ValueError("device 'cuda' requested but CUDA is not available")
        if args.max_steps < 1:
            raise ValueError("--max-steps must be >= 1")
        if args.scheduler is not None and args.shard != (0, 1):
            raise ValueError("--shard and --scheduler exclude each other: the cluster takes every g node")
        out = Path(args.out).resolve() if args.scheduler is not None else args.out  # workers need its full path
        with output_lock(args.out, "--out", shard_part(args.shard)), \
                engine.job(args.scheduler, "lut", shared=[Path(out).parent], threads=max(1, args.threads),
                        progress=not args.no_progress) as job:
            build_lut(
                out, args.albedo_n, args.g_n, args.photons, seed=args.seed, device=args.device,
                albedo_range=(args.albedo_min, args.albedo_max), g_range=(args.g_min, args.g_max),
                g_nodes=args.g_nodes, max_steps=args.max_steps, compile=compile_, shard=args.shard,
                progress=not args.no_progress, log=lambda s: print(s, file=sys.stderr), job=job,
            )
    except (ValueError, engine.TaskError) as exc:
        return error_status(exc)
    return 0
