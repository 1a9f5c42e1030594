"""``python -m training report``: one summary of a dataset, its fits, a model and a validation run.

    python -m training report [--dataset DIR] [--fits DIR] [--model-dir DIR] [--validation DIR]
                              [--out FILE.md] [--overwrite] [--json]

Reads what the other commands wrote and recomputes nothing heavy:

* ``--dataset``: per split what ``dataset --summary`` reports (``training.data.summary.split_summary``: tones,
  photons, estimator, times, sizes); nothing is written into the folder.
* ``--fits``: per split the tones fitted (the ``done`` masks of ``<split>_fits.h5`` or its shards), of those
  selected and of the split; with ``--dataset`` also the mean errors of ``fit --summary``
  (``training.fit.dataset.summarise``; reads the fitted tones' profiles once).
* ``--model-dir`` (default: the shipped model, ``training.paths.SHIPPED_MODEL_DIR``): the card
  ``skin_inversion.json`` (counts, K, commands, date, headline validation numbers) and each graph's SHA-256
  checked against its file.
* ``--validation``: the headline rows of a ``validate --out`` folder's ``tables.json``.

A part not asked for, or whose files are not there, is skipped with a one-line note; a folder given that does
not exist is an error (exit 2).  Markdown to stdout, or to ``--out`` (never overwritten without
``--overwrite``); ``--json`` for one JSON object.  Paths are written as shipped files write them
(``training.paths.portable``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from exporters.cli_io import OneLineParser
from training.commands.options import atomic_file, check_input, check_output_file, command, error_status
from training.data.build import SPLITS
from training.paths import SHIPPED_MODEL_DIR, portable, portable_strings

CARD_NAME = "skin_inversion.json"


def dataset_part(folder: Path) -> tuple[dict, list[str]]:
    """Per split the ``dataset --summary`` record of ``folder``; notes for the splits missing."""
    from training.data.summary import split_summary

    splits, notes = {}, []
    for split in SPLITS:
        if (folder / f"{split}.h5").is_file():
            splits[split] = split_summary(folder, split)
        else:
            shards = len(list(folder.glob(f"{split}.shard*of*.h5")))
            notes.append(f"dataset: no {split}.h5" + (f" ({shards} shard files: run `dataset --merge`)" if shards
                                                        else ""))
    return splits, notes


def fits_part(folder: Path, dataset: Path | None) -> tuple[dict, list[str]]:
    """Per split the fitted counts of the fits in ``folder`` and, with ``dataset``, their mean errors."""
    from training.fit.dataset import fitted_counts, summarise
    from training.train.data import fits_files

    splits, notes = {}, []
    for split in SPLITS:
        files = fits_files(folder, split)
        if not files:
            notes.append(f"fits: no {split}_fits*.h5")
            continue
        splits[split] = fitted_counts(files)
        if dataset is None:
            continue
        try:
            splits[split]["errors"] = summarise(dataset, files)
        except (OSError, ValueError, KeyError) as exc:
            notes.append(f"fits: no mean errors for {split} ({exc})")
    if dataset is None and splits:
        notes.append("fits: mean errors need --dataset (the profiles' noise floor)")
    return splits, notes


def model_part(folder: Path) -> tuple[dict | None, list[str]]:
    """The card of ``folder`` (selected entries) and its files' SHA-256 checks; None when there is no card."""
    from training.export.card import check_files, summary

    path = folder / CARD_NAME
    if not path.is_file():
        return None, [f"model: no {CARD_NAME} in {portable(folder)}"]
    card = json.loads(path.read_text())
    checks = check_files(card, folder)
    notes = [f"model: {name} SHA-256 does not match the card ({'missing' if c['actual'] is None else 'changed'})"
             for name, c in checks.items() if not c["ok"]]
    return {"summary": summary(card), "created": card.get("created"), "K": card.get("K"),
            "dataset": {k: v for k, v in card.get("dataset", {}).items() if not k.endswith("_attrs")},
            "commands": {"train": card.get("training", {}).get("commands", []),
                         "export": card.get("export", {}).get("command"),
                         "validate": card.get("validation", {}).get("command")},
            "metrics": card.get("metrics", {}), "validation": card.get("validation"), "files": checks}, notes


def validation_part(folder: Path) -> tuple[dict | None, list[str]]:
    """The headline numbers (``training.validate.record.headline``) of ``folder``/tables.json."""
    path = folder / "tables.json"
    if not path.is_file():
        return None, [f"validation: no tables.json in {portable(folder)}"]
    from training.validate.record import headline

    try:
        record = headline(json.loads(path.read_text()))
    except (KeyError, TypeError, AttributeError) as exc:
        return None, [f"validation: {portable(path)} lacks {exc} (a quick or older run?)"]
    record.pop("created")  # headline() stamps the time it is called
    return record, []


def collect(args: argparse.Namespace) -> dict:
    """The report as one JSON-able record (module docstring)."""
    report: dict = {"dataset": None, "fits": None, "model": None, "validation": None, "notes": []}
    if args.dataset is None:
        report["notes"].append("dataset: not given (--dataset DIR)")
    else:
        splits, notes = dataset_part(args.dataset)
        report["dataset"] = {"path": portable(args.dataset), "splits": splits}
        report["notes"] += notes
    if args.fits is None:
        report["notes"].append("fits: not given (--fits DIR)")
    else:
        splits, notes = fits_part(args.fits, args.dataset)
        report["fits"] = {"path": portable(args.fits), "splits": splits}
        report["notes"] += notes
    model, notes = model_part(args.model_dir)
    if model is not None:
        report["model"] = {"path": portable(args.model_dir), **model}
    report["notes"] += notes
    if args.validation is None:
        report["notes"].append("validation: not given (--validation DIR, a `validate --out` folder)")
    else:
        validation, notes = validation_part(args.validation)
        if validation is not None:
            report["validation"] = {"path": portable(args.validation), **validation}
        report["notes"] += notes
    return portable_strings(report)


def _n(x, digits: int = 2) -> str:
    if x is None:
        return "—"
    if isinstance(x, bool) or isinstance(x, str):
        return str(x)
    return f"{x:,}" if isinstance(x, int) else f"{x:.{digits}f}"


def _table(header: list[str], rows: list[list], digits: int = 2) -> list[str]:
    return ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|",
            *("| " + " | ".join(_n(v, digits) for v in r) + " |" for r in rows), ""]


def _dataset_md(part: dict) -> list[str]:
    rows = [[s, d["tones"], d["of"], d["photons"], d["method"], d["reweight_or_simulate_s"], d["walk_s"],
             (d["file_bytes"] + d["walk_bytes"]) / 1e6] for s, d in part["splits"].items()]
    return [f"## Dataset (`{part['path']}`)", "",
            *_table(["split", "tones done", "of", "photons", "estimator", "reweight/simulate (s)", "walk (s)",
                     "size (MB)"], rows)]


def _fits_md(part: dict) -> list[str]:
    rows = [[s, d["fitted"], d["selected"], d["of"], ",".join(map(str, d["ks"])), d["wavelengths"], d["files"]]
            for s, d in part["splits"].items()]
    out = [f"## Fits (`{part['path']}`)", "",
           *_table(["split", "tones fitted", "selected", "of split", "K", "wavelengths", "files"], rows)]
    err = [[s, int(k), e["shape_rmse"], e["shape_excess"], e["refl_rel_err"], d["errors"]["noise"]]
           for s, d in part["splits"].items() if "errors" in d for k, e in d["errors"]["K"].items()]
    if err:
        out += ["Mean over the fitted tones × wavelengths (`fit --summary`):", "",
                *_table(["split", "K", "shape RMSE", "shape excess", "refl. rel. error", "MC noise"], err, 3)]
    return out


def _headline_md(v: dict) -> list[str]:
    """The gate's ΔE76 rows, the profile error and the goals of a validation headline (``headline``)."""
    gate = v.get("gate", {})
    named = [("network", gate.get("nn_delta_e")), ("network, painted colour", gate.get("nn_painted_delta_e")),
             ("network's decoder", gate.get("nn_decoder_delta_e")),
             *((f"joint fit {k}", d) for k, d in gate.get("joint_opt_delta_e", {}).items()),
             *((f"baseline {m}", d) for m, d in gate.get("baseline_delta_e", {}).items())]
    rows = [[name, d.get("representative"), d.get("outlier"), d.get("all")] for name, d in named if d]
    out = [f"Validation `{v.get('command', '?')}`" + (f" ({v['created']})" if v.get("created") else "") + ":", "",
           *_table(["gate ΔE76", "representative", "outlier", "all"], rows)]
    prof = v.get("profile_shape") or {}
    if prof:
        out += [f"Profile shape error ({prof.get('n_tones')} validation tones): "
                + ", ".join(f"{k} {_n(prof[k], 3)}" for k in ("K1", "K2", "K3") if k in prof)
                + f"; K = 1 → 2 reduction {_n(prof.get('K1_to_K2_reduction'), 3)}.", ""]
    goals = dict(v.get("goals") or {})
    targets = goals.pop("network_targets", [])  # the network's targets: a list, each with its own goal
    out += [f"- goal `{name}`: ours {_n(g.get('ours'), 3)}, paper {_n(g.get('paper'), 3)}, "
            f"{'met' if g.get('met') else 'not met'}" for name, g in goals.items()]
    out += [f"- target: {t.get('what')}: ours {_n(t.get('ours'), 3)}, at most {_n(t.get('target'), 3)}, "
            f"{'met' if t.get('met') else 'not met'}" for t in targets]
    return out + ([""] if goals or targets else [])


def _without_notes(command: str) -> str:
    """``command`` with the text of each ``--note`` (paragraphs, in the card's ``notes``) shown as ``…``."""
    import shlex

    words = shlex.split(command)
    return shlex.join(["…" if i and words[i - 1] == "--note" else w for i, w in enumerate(words)])


def _model_md(part: dict) -> list[str]:
    ds, cmds, val = part["dataset"], part["commands"], part["metrics"].get("validation", {})
    out = [f"## Model (`{part['path']}`)", "", part["summary"] + ".", "",
           f"- created {part['created']}, K = {part['K']}",
           f"- dataset `{ds.get('path')}`: {_n(ds.get('n_train'))} training + {_n(ds.get('n_validation'))} validation "
           f"tones at {_n(ds.get('photons'))} photons; fitted {_n(ds.get('n_train_fitted'))} + "
           f"{_n(ds.get('n_validation_fitted'))} tones at {_n(ds.get('fitted_wavelengths'))} wavelengths",
           *(f"- train: `{c}`" for c in cmds["train"]),
           f"- export: `{_without_notes(cmds['export'])}`" if cmds["export"] else "- export: (no command recorded)"]
    if val:
        out.append(f"- on its {_n(val.get('n_tones'))} validation tones: colour round trip ΔE76 mean "
                   f"{_n(val.get('enc_delta_e76', {}).get('mean'))}, the mixture's ΔE76 mean "
                   f"{_n(val.get('mixture_delta_e76', {}).get('mean'))}")
    out += ["", *_table(["file", "SHA-256 (card)", "matches the file"],
                        [[f"`{n}`", f"`{c['expected']}`", "yes" if c["ok"] else
                          ("**NO: file missing**" if c["actual"] is None else f"**NO: file is `{c['actual']}`**")]
                         for n, c in part["files"].items()])]
    if part["validation"]:
        out += _headline_md(part["validation"])
    return out


def markdown(report: dict) -> str:
    """The report record (``collect``) as Markdown."""
    out = ["# Report", ""]
    if report["dataset"]:
        out += _dataset_md(report["dataset"])
    if report["fits"]:
        out += _fits_md(report["fits"])
    if report["model"]:
        out += _model_md(report["model"])
    if report["validation"]:
        out += [f"## Validation run (`{report['validation']['path']}`)", "", *_headline_md(report["validation"])]
    if report["notes"]:
        out += ["## Notes", "", *(f"- {n}" for n in report["notes"]), ""]
    return "\n".join(out)


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="python -m training report", description=__doc__.splitlines()[0],
                      formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    p.add_argument("--dataset", type=Path, help="dataset folder (`python -m training dataset --out`)")
    p.add_argument("--fits", type=Path, help="fits folder (`python -m training fit --dataset ... --out`)")
    p.add_argument("--model-dir", type=Path, default=SHIPPED_MODEL_DIR,
                   help=f"folder of {CARD_NAME} and its graphs (default: the shipped model)")
    p.add_argument("--validation", type=Path, help="a `python -m training validate --out` folder (tables.json)")
    p.add_argument("--out", type=Path, help="write the report there instead of stdout")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    p.add_argument("--json", action="store_true", help="one JSON object instead of Markdown")
    return p


@command("report")
def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    inputs = []
    for option in ("dataset", "fits", "model_dir", "validation"):
        folder = getattr(args, option)
        if folder is not None:
            name = f"--{option.replace('_', '-')}"
            check_input(folder, name, "folder")
            inputs.append((name, folder))
            for h5 in sorted(folder.glob("*.h5")):
                check_input(h5, "HDF5 file", "h5")
    if args.out is not None:
        check_output_file(args.out, "--out", overwrite=args.overwrite, inputs=tuple(inputs))
    try:
        report = collect(args)
    except (ValueError, OSError) as exc:
        return error_status(exc)
    text = json.dumps(report, indent=1) + "\n" if args.json else markdown(report)
    if args.out is None:
        sys.stdout.write(text)
    else:
        with atomic_file(args.out, "w") as f:
            f.write(text)
        print(f"wrote {portable(args.out)}")
    return 0
