"""Bake an RGB skin albedo texture into spectral-skin subsurface maps (docs/contracts.md §4), headless.

    python blender_addon/bake.py --albedo IMAGE --out DIR [--target cycles,physical,spectral,openpbr]
        [--colorspace auto|srgb|linear] [--unit-scale M_PER_UNIT] [--overwrite] [--model PATH] [--threads N]
        [--model-colour] [--exact] [--table PATH] [--force] [--uv-mask IMAGE] [--prune-share S]
        [--exr-compression piz|zip|...] [--float-maps]
        [--melanin V] [--blood V] [--oxygenation V] [--melanin-map IMAGE] [--blood-map IMAGE] [--oxygenation-map IMAGE]
    blender -b --factory-startup --python blender_addon/bake.py -- --albedo IMAGE --out DIR ...

By default the maps render the painted albedo, per channel (exporters.painted); ``--model-colour`` renders the
model's own reflectance instead (the colour of the biophysical skin the network found).  Texels are looked
up in the fast-path table shipped beside the model (``skin_inversion_table.npz``, exporters.texel_table; colours
outside its domain get the nearest skin colour's maps, as the live group renders them); ``--exact`` evaluates
every distinct colour with the model.  Re-running a bake whose maps in DIR are up to date (same image content,
model and options) does nothing and says so (``--force`` re-bakes).

Skin edits (exporters.skin_edits): ``--melanin V`` and ``--blood V`` multiply the tone's melanin and blood fractions,
``--oxygenation V`` shifts its oxygen saturation; ``--melanin-map IMAGE`` etc. weigh an edit per texel (a mask, 0 =
as painted, 1 = the full edit), as a Mix node before the live group's input would.

Writes float EXR maps (Non-Color) and IMAGE-stem_maps.json into DIR (created if missing).  Exit status 0 on
success, 2 with a one-line error on stderr for bad input (missing/unreadable image, NaN or negative
texels, missing or wrong model, existing files without --overwrite, read-only folder, bad arguments).
Nothing in DIR is overwritten without --overwrite, and a failed bake leaves DIR as it was.

This file is a script: it imports ``exporters`` (numpy, onnxruntime, OpenImageIO) and never bpy, so it
runs with the plain Python of the project venv (where the bpy module is also installed) as well as
inside Blender, whose own Python finds onnxruntime in the installed extension's wheel folder (Blender puts
that folder on ``sys.path`` itself).  ``exporters`` is the package beside this file, found without changing
``sys.path``: in an installed extension the extension's own (``bl_ext.<repo>.spectral_skin_sss.exporters``),
in the repository the checkout's top-level ``exporters`` (:func:`core_package`).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import importlib
import importlib.util
import os
import sys
import time
from pathlib import Path
from types import ModuleType

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
DEFAULT_MODEL = HERE / "models" / "skin_inversion.onnx"
EXIT_BAD_INPUT = 2


def _script_argv(argv: list[str] | None) -> list[str]:
    """Arguments meant for this script: everything after ``--`` when run by Blender, else argv[1:]."""
    if argv is not None:
        return argv
    if "--" in sys.argv:
        return sys.argv[sys.argv.index("--") + 1:]
    return sys.argv[1:]


def _package_holding(folder: Path) -> str | None:
    """Name of the imported package that ``folder`` is (its ``__init__.py``) or is a subpackage of (a package whose
    ``__path__`` holds ``folder.parent``): ``bl_ext.user_default.spectral_skin_sss`` for an installed extension.
    Files are compared by identity (:func:`_file_id`, links followed): one stat per package, where resolving every
    module's path walks each of its folders (seconds in a process that has imported thousands of modules)."""
    target = _file_id(folder / "__init__.py")
    if target is None:
        return None
    for name, module in list(sys.modules.items()):
        file = getattr(module, "__file__", None)
        if "." in name and isinstance(file, (str, os.PathLike)) and os.path.basename(file) == "__init__.py" \
                and _file_id(file) == target:
            return name
    parent = _file_id(folder.parent)
    for name, module in list(sys.modules.items()):
        try:
            paths = list(getattr(module, "__path__", None) or [])
        except TypeError:  # a module with an unusual __path__ is not a package of files
            continue
        if any(_file_id(p) == parent for p in paths):
            return f"{name}.{folder.name}"
    return None


def _file_id(path) -> tuple[int, int] | None:
    """(device, inode) of ``path`` after links, what os.path.samefile compares; None where it is not a path or cannot
    be read."""
    try:
        st = os.stat(path)
    except (OSError, ValueError, TypeError):
        return None
    return st.st_dev, st.st_ino


@functools.cache
def core_package() -> str:
    """The full name of the ``exporters`` package beside this file, imported (see the module docstring); found once
    per process."""
    if __package__:  # imported as a module: blender_addon.bake or <extension>.blender_addon.bake
        home = __package__.rpartition(".")[0]
        name = f"{home}.exporters" if home else "exporters"
    elif (home := _package_holding(ROOT)) is not None:
        name = f"{home}.exporters"
    else:
        name = "exporters"
        if name not in sys.modules:
            spec = importlib.util.find_spec(name)
            mine = ROOT / name / "__init__.py"
            if spec is None or spec.origin is None or Path(spec.origin).resolve() != mine:
                spec = importlib.util.spec_from_file_location(name, mine,
                                                              submodule_search_locations=[str(ROOT / name)])
                module = importlib.util.module_from_spec(spec)
                sys.modules[name] = module
                spec.loader.exec_module(module)
    importlib.import_module(name)
    return name


def core(module: str) -> ModuleType:
    """``exporters.<module>`` of the package beside this file (:func:`core_package`)."""
    return importlib.import_module(f"{core_package()}.{module}")


def build_parser() -> argparse.ArgumentParser:
    """The command line; its defaults are the library's (exporters.bake.BakeOptions)."""
    bake, cli_io, image_input = core("bake"), core("cli_io"), core("image_input")
    reflectance_tables = core("reflectance_tables")

    defaults = bake.BakeOptions()
    p = cli_io.OneLineParser(prog="bake.py", description=__doc__.splitlines()[0])
    p.add_argument("--albedo", required=True, help="albedo image (PNG/TIFF 8 or 16 bit, EXR, ...); a UDIM image as "
                                                   "its tiles' pattern, e.g. skin.<UDIM>.png: every tile is baked")
    p.add_argument("--out", required=True, help="output folder (created if missing)")
    p.add_argument("--target", default="cycles", help="comma-separated subset of cycles,physical,spectral,openpbr "
                                                      "(default cycles; openpbr: OpenPBR maps, a MaterialX "
                                                      "document and a USD layer, docs/user/other_renderers.md)")
    p.add_argument("--colorspace", default="auto", choices=image_input.COLORSPACES,
                   help="how the image is encoded; auto: sRGB unless the file says linear or stores floats")
    p.add_argument("--unit-scale", type=float, default=defaults.unit_scale_m, metavar="M_PER_UNIT",
                   help="metres per Blender unit for the radius maps (the scene's Unit Scale; default "
                        f"{defaults.unit_scale_m:g})")
    p.add_argument("--overwrite", action="store_true", help="replace existing maps in the output folder")
    p.add_argument("--model", default=str(DEFAULT_MODEL), help="skin_inversion.onnx (default: the bundled one)")
    p.add_argument("--threads", type=cli_io.non_negative_int, default=0, help="onnxruntime CPU threads (0 = all cores)")
    p.add_argument("--memory-mb", type=cli_io.positive_float, default=float(defaults.memory_mb),
                   help="memory budget of the bake's working arrays: the decoded image, one band of maps, one "
                        f"table step, one inference chunk (MiB, default {defaults.memory_mb:g}); an image whose "
                        "header claims more texels than it can decode is refused before decoding")
    p.add_argument("--model-colour", action="store_true",
                   help="render the model's own reflectance (the colour of the skin the network found, physically "
                        "consistent, often darker than painted) instead of the painted albedo (the default)")
    p.add_argument("--match-exposure", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--ior", type=cli_io.in_range(reflectance_tables.IOR_MIN, reflectance_tables.IOR_MAX),
                   default=defaults.ior,
                   help=f"IOR of the Cycles closures (the node group's IOR input; default {defaults.ior:g}, tissue)")
    p.add_argument("--exact", action="store_true",
                   help="evaluate every distinct colour with the model instead of the fast-path table")
    p.add_argument("--table", default=None, metavar="PATH",
                   help="fast-path table (default: <model stem>_table.npz beside the model)")
    p.add_argument("--force", action="store_true", help="re-bake even if DIR holds an up-to-date bake")
    p.add_argument("--uv-mask", default=None, metavar="IMAGE",
                   help="image of the texels the mesh's UVs cover (non-zero = covered, same size as the albedo); "
                        "others get the maps of the most common covered colour")
    p.add_argument("--prune-share", type=cli_io.fraction, default=None, metavar="S",
                   help="drop components below this share of the colour at every texel (default "
                        f"{bake.DEFAULT_PRUNE_SHARE:g}; 0 keeps all)")
    p.add_argument("--exr-compression", default=None,
                   help=f"EXR compression of the maps (default {defaults.compression})")
    p.add_argument("--float-maps", action="store_true",
                   help="store every map as 32-bit float (default on the fast path: colour, weight and anisotropy "
                        "maps as half floats, step <= 2.4e-4, which halves the write)")
    skin_edits = core("skin_edits")
    for name in skin_edits.CONTROLS:
        lo, hi = skin_edits.CONTROL_RANGES[name]
        neutral = skin_edits.NEUTRAL[skin_edits.CONTROLS.index(name)]
        what = ("shifts the blood's oxygen saturation by" if name == "oxygenation"
                else f"multiplies the {name} fraction by")
        p.add_argument(f"--{name}", type=cli_io.in_range(lo, hi), default=neutral, metavar="V",
                       help=f"skin edit: {what} V, in [{lo:g}, {hi:g}] (default {neutral:g}: as painted)")
        p.add_argument(f"--{name}-map", default=None, metavar="IMAGE",
                       help=f"mask (first channel, 0-1, albedo's size) weighing the --{name} edit per texel")
    p.add_argument("--quiet", action="store_true")
    return p


def check_paths(args: argparse.Namespace) -> None:
    """cli_io.InputError for a missing, truncated or disguised input and an --out that cannot be the folder."""
    cli_io = core("cli_io")

    inputs = []
    for option, value, kind in (("--albedo", args.albedo, "image"), ("--model", args.model, "onnx"),
                                ("--table", args.table, "npz"), ("--uv-mask", args.uv_mask, "image"),
                                *((f"--{n}-map", getattr(args, f"{n}_map"), "image")
                                  for n in ("melanin", "blood", "oxygenation"))):
        if value is not None and (option not in ("--albedo", "--model") or Path(value).exists()):
            cli_io.check_input(value, option, kind)  # a missing image or model: the library's own message
        inputs.append((option, value))
    cli_io.check_output_folder(args.out, "--out", inputs=tuple(inputs), writable=False)  # may hold a finished bake


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(_script_argv(argv))
    except SystemExit as exc:  # --help (0) or a one-line usage error (2)
        return int(exc.code or 0)
    bake, cli_io, image_input = core("bake"), core("cli_io"), core("image_input")
    inference, maps = core("inference"), core("maps")

    bad_input = (FileNotFoundError, FileExistsError, PermissionError, NotADirectoryError, image_input.ImageError,
                 inference.ModelError, bake.BakeError, ValueError)
    if args.match_exposure:
        print("bake.py: error: --match-exposure is gone: the maps now render the painted albedo by default (its "
              "brightness and its hue); --model-colour renders the model's own reflectance", file=sys.stderr)
        return EXIT_BAD_INPUT
    out = Path(args.out)
    created = False
    results = []
    try:
        check_paths(args)
        created = maps.make_output_folder(out)
        options = bake.BakeOptions(targets=bake.parse_targets(args.target), unit_scale_m=args.unit_scale,
                                   threads=args.threads, memory_mb=args.memory_mb,
                                   model_colour=args.model_colour, ior=args.ior,
                                   overwrite=args.overwrite, exact=args.exact, table_path=args.table,
                                   force=args.force, texel_mask=_read_mask(args.uv_mask, args.memory_mb),
                                   prune_share=_prune_share(args, bake, image_input),
                                   compression=args.exr_compression or maps.DEFAULT_COMPRESSION,
                                   half_maps=False if args.float_maps else None,
                                   **_edit_options(args, args.memory_mb))
        last = [0.0]

        def progress(fraction: float) -> None:
            if not args.quiet and (fraction - last[0] >= 0.1 or fraction >= 1.0):
                last[0] = fraction
                print(f"bake.py: {100 * fraction:.0f} %", flush=True)

        t0 = time.perf_counter()
        # one bake per folder; a read-only folder can only hold a finished bake (reused) or fail its checks
        lock = cli_io.output_lock(out, "--out") if os.access(out, os.W_OK) else contextlib.nullcontext()
        with lock:
            albedos = _albedo_files(args.albedo, args.uv_mask, image_input)
            for i, albedo in enumerate(albedos):
                if not args.quiet and albedo != args.albedo:
                    print(f"bake.py: tile {Path(albedo).name}", flush=True)
                tile_options = options if albedo == args.albedo else bake.udim_tile_options(
                    options, args.albedo, last=i == len(albedos) - 1)
                results.append(bake.bake(albedo, out, args.model, tile_options, colorspace=args.colorspace,
                                         progress=progress))
                last[0] = 0.0
    except bad_input as exc:
        _remove_written(results)
        if created:
            _remove_if_empty(out)
        print(f"bake.py: error: {bake.one_line(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        _remove_written(results)
        if created:
            _remove_if_empty(out)
        print(f"\nbake.py: interrupted: nothing in {out} was changed (maps are published only when all are "
              "written); run the same command again", file=sys.stderr)
        return cli_io.EXIT_INTERRUPTED
    except BaseException:
        _remove_written(results)
        if created:
            _remove_if_empty(out)
        raise
    for result in results:
        _report(result, out, args.quiet, t0)
    return 0


def _prune_share(args, bake, image_input) -> float:
    """--prune-share, whose default is 0 for a UDIM albedo: each tile then keeps all K components, so every map
    exists for every tile (a pruned component missing from one tile would leave a hole in that map's UDIM set)."""
    if image_input.UDIM_TOKEN not in args.albedo:
        return bake.DEFAULT_PRUNE_SHARE if args.prune_share is None else args.prune_share
    if args.prune_share:
        raise ValueError("--prune-share drops components tile by tile, so a UDIM albedo's maps could miss tiles: "
                         "leave it out for UDIM albedos")
    return 0.0


def _albedo_files(albedo: str, uv_mask: str | None, image_input) -> list[str]:
    """The image files to bake: ``albedo`` itself, or every tile of a UDIM pattern (exporters.image_input)."""
    if image_input.UDIM_TOKEN not in albedo:
        return [albedo]
    if uv_mask is not None:
        raise ValueError("--uv-mask takes one image: bake the tiles of a UDIM albedo one by one to give each its mask")
    return [str(path) for _, path in image_input.udim_tiles(albedo)]


def _remove_written(results: list) -> None:
    """Undo the tiles already baked in this run when a later one fails (the folder is left as it was)."""
    for result in results:
        if not result.reused:
            for path in [*result.files, result.json_path]:
                Path(path).unlink(missing_ok=True)


def _report(result, out: Path, quiet: bool, t0: float) -> None:
    for note in result.notes:
        if note.startswith("warning: "):
            print(f"bake.py: {note}", file=sys.stderr)
        elif not quiet:
            print(f"bake.py: note: {note}")
    if not quiet:
        verb = "kept" if result.reused else "wrote"
        print(f"bake.py: {verb} {len(result.files)} maps (K={result.k}) and {result.json_path.name} in {out} "
              f"in {time.perf_counter() - t0:.1f} s")


def _read_mask(path: str | None, memory_mb: float | None = None):
    """The --uv-mask image as (H, W) bool (any non-zero colour channel = covered), or None."""
    if path is None:
        return None
    image = core("image_input").read_albedo(path, colorspace="linear", memory_mb=memory_mb)
    return (image.rgb > 0).any(axis=2)


def _edit_options(args: argparse.Namespace, memory_mb: float | None = None) -> dict:
    """BakeOptions' ``edit`` and ``edit_masks`` from --melanin/--blood/--oxygenation and their --*-map masks."""
    skin_edits = core("skin_edits")
    edit = skin_edits.SkinEdit(**{name: getattr(args, name) for name in skin_edits.CONTROLS})
    masks = {}
    for name in skin_edits.CONTROLS:
        path = getattr(args, f"{name}_map")
        if path is not None:
            masks[name] = core("image_input").read_albedo(path, colorspace="linear", memory_mb=memory_mb).rgb[..., 0]
    return {"edit": edit, "edit_masks": masks or None}


def _remove_if_empty(folder: Path) -> None:
    try:
        os.rmdir(folder)
    except OSError:
        pass


if __name__ == "__main__":
    code = main()
    if code:
        sys.exit(code)
