"""The model card ``skin_inversion.json`` (docs/contracts.md §3): what the shipped graphs are and how they were made.

Contents: the files with SHA-256, size and I/O; K and the spectral grid; the input domain; the
dataset (size, photons, preset, seeds) and fits; the LUT; the exact commands that trained and exported
the model; the training losses of every stage; the colour errors measured on the validation tones;
the export checks (torch vs onnxruntime parity, float16 cost); placeholders for the validation tables
of ``python -m training validate``; and free-text notes (what the model is and is not).
"""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path

import h5py

from exporters.cli_io import atomic_file
from exporters.constants import WAVELENGTH_STEP_NM, WAVELENGTHS_NM
from exporters.maps import sha256_file
from training.export.graphs import output_shapes
from training.model.chain import DECODER_OUTPUTS, INVERSION_OUTPUTS
from training.model.config import FALLBACK_ALBEDO_RGB
from training.paths import portable, portable_strings

INPUT_DOMAIN = (
    "albedo_rgb: linear sRGB (D65). A row with any NaN/Inf component is replaced by the fallback colour "
    f"{list(FALLBACK_ALBEDO_RGB)}; then each component is clamped to [0, 1]. The exposure is computed from "
    "the sanitised colour, so Y(exposure * rgb(reflectance)) = Y(albedo_rgb) for inputs in [0, 1]^3. "
    "biophysical: a row with NaN/Inf is replaced by the centre of the sampling ranges, then each component is "
    "clamped to its range. Callers (exporters) should reject non-finite pixels with an error first."
)
VALIDATION_PLACEHOLDER = {
    "status": "not run: filled by `python -m training validate` (docs/contracts.md §6)",
    "rendering_delta_e76": None,
    "banded_shape_error": None,
    "spectral_angle": None,
    "profile_error": None,
}


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _io(names: tuple[str, ...], k: int) -> dict[str, list]:
    shapes = output_shapes(k) | {"albedo_rgb": ("N", 3)}
    return {n: list(shapes[n]) for n in names}


def _h5_attrs(path: Path) -> dict:
    """The file's attributes (their absolute paths are made portable where the card is written)."""
    if not path.is_file():
        return {}
    with h5py.File(path, "r") as f:
        return {k: (v.item() if hasattr(v, "item") else str(v)) for k, v in f.attrs.items()}


def _fits_attrs(fits_dir: Path) -> dict:
    """Attributes of the training split's fits (the first shard's when sharded; ``shard`` then says which)."""
    from training.train.data import fits_files

    files = fits_files(fits_dir, "train")
    return _h5_attrs(files[0]) if files else {}


def build_card(run: dict, graphs: dict[str, bytes], weights: str, parity: dict, f16_cost: dict | None,
               export_command: str, notes: list[str]) -> dict:
    """The card as a dict (``run``: the run folder's run.json record)."""
    k = run["model"]["k"]
    files = {}
    for name, data in graphs.items():
        ins = ("albedo_rgb",) if name == "skin_inversion.onnx" else ("biophysical",)
        outs = INVERSION_OUTPUTS if name == "skin_inversion.onnx" else DECODER_OUTPUTS
        files[name] = {"sha256": sha256_bytes(data), "bytes": len(data), "inputs": _io(ins, k),
                       "outputs": _io(outs, k)}
    dataset = Path(run["dataset"])
    return {
        "name": "Spectral Skin SSS inversion",
        "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "files": files,
        "K": k,
        "wavelength_nm": {"first": float(WAVELENGTHS_NM[0]), "last": float(WAVELENGTHS_NM[-1]),
                          "step": WAVELENGTH_STEP_NM, "count": int(WAVELENGTHS_NM.size)},
        "units": {"sigma_t": "cm^-1", "biophysical": "f_mel, f_blood, t_epi [cm], so2, b_mel",
                  "albedo_rgb": "linear sRGB (D65)"},
        "input_domain": INPUT_DOMAIN,
        "architecture": run["model"],
        "dataset": {"path": portable(dataset), **run.get("dataset_info", {}),
                    "train_attrs": _h5_attrs(dataset / "train.h5"),
                    "validation_attrs": _h5_attrs(dataset / "validation.h5")},
        "fits": {"path": portable(run.get("fits")),
                 "train_attrs": _fits_attrs(Path(run["fits"])) if run.get("fits") else {}},
        "lut": {"path": portable(run["lut"]), "sha256": run["lut_sha256"]},
        "training": {"commands": run.get("commands", []), "config": run["train"], "losses": run.get("losses", {}),
                     "slab_depth_cm": run.get("slab_depth_cm")},
        "metrics": run.get("metrics", {}),
        "export": {"command": export_command, "weights_dtype": weights, "parity_torch_vs_onnxruntime": parity,
                   "float16_rounding_cost": f16_cost},
        "validation_tables": VALIDATION_PLACEHOLDER,
        "notes": notes,
    }


def write_card(path: Path, card: dict) -> None:
    """Write the card as JSON (atomically: a temporary file in the same folder, then renamed)."""
    with atomic_file(path, "w") as f:
        f.write(json.dumps(portable_strings(card), indent=2) + "\n")


def update_validation(path: Path, validation: dict) -> None:
    """Set the card's ``validation`` entry (the headline numbers of ``python -m training validate``).

    Every other key is kept as it is, except the export's placeholder ``validation_tables`` (when it still
    is the placeholder), whose status then points to ``validation``.  Written atomically (temporary file
    renamed into place); ValueError if ``path`` is not a JSON object.
    """
    path = Path(path)
    try:
        card = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"cannot read the model card {path}: {exc}") from None
    if not isinstance(card, dict):
        raise ValueError(f"{path} is not a model card (a JSON object).")
    card["validation"] = validation
    if card.get("validation_tables") == VALIDATION_PLACEHOLDER:
        card["validation_tables"] = {"status": "filled: see `validation` (python -m training validate)"}
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(portable_strings(card), indent=2) + "\n")
    tmp.replace(path)


def check_files(card: dict, folder: Path) -> dict[str, dict]:
    """Each graph the card lists, checked against the file of that name in ``folder``: ``expected`` (the card's
    SHA-256), ``actual`` (the file's, None when it is missing), ``ok``."""
    checks = {}
    for name, entry in card.get("files", {}).items():
        path = Path(folder) / name
        actual = sha256_file(path) if path.is_file() else None
        checks[name] = {"expected": entry.get("sha256"), "actual": actual, "ok": actual == entry.get("sha256")}
    return checks


def summary(card: dict) -> str:
    """One line saying what the model of ``card`` (a parsed model card) is, from the card alone: its name, K,
    export date, the dataset it was trained on (preset, tone counts, photons per wavelength) and the colour
    errors it was measured at (validation round trip; the validation gate's representative tones).  Whatever
    the card lacks is left out."""
    head = [card.get("name", "unnamed model")]
    if "K" in card:
        head.append(f"K = {card['K']}")
    if card.get("created"):
        head.append(f"exported {str(card['created'])[:10]}")
    facts = []
    ds = card.get("dataset", {})
    if ds.get("n_train"):
        preset = ds.get("train_attrs", {}).get("preset")
        trained = f"trained on {'the ' + preset + ' dataset, ' if preset else ''}{ds['n_train']:,} training"
        if ds.get("n_validation"):
            trained += f" + {ds['n_validation']:,} validation"
        trained += " tones"
        if ds.get("photons"):
            trained += f" at {ds['photons']:,} photons per wavelength"
        facts.append(trained)
    round_trip = card.get("metrics", {}).get("validation", {}).get("enc_delta_e76", {}).get("mean")
    if round_trip is not None:
        exposure = card["metrics"]["validation"].get("exposure_error", {}).get("mean")
        beside = f" (exposure error {exposure:.2f} mean)" if exposure is not None else ""
        facts.append(f"colour round trip ΔE76 {round_trip:.2f} mean{beside} on its validation tones")
    gate = card.get("validation", {}).get("gate", {}).get("nn_delta_e", {}).get("representative")
    if gate is not None:
        facts.append(f"validation gate ΔE76 {gate:.2f} on the representative tones")
    return ", ".join(head) + (f": {'; '.join(facts)}" if facts else "")
