"""Physical art direction of skin: the Melanin, Blood and Oxygenation controls and their exact answer.

The inversion gives every painted colour c its tone Enc(c) = (f_mel, f_blood, t_epi, so2, b_mel) and an exposure;
the decoder turns any tone into its reflectance spectrum and K media.  An *edit* changes the tone:

* **Melanin** m multiplies the epidermal melanin volume fraction f_mel (1 = as painted),
* **Blood** b multiplies the dermal blood volume fraction f_blood (1 = as painted),
* **Oxygenation** o shifts the blood's oxygen saturation so2 (0 = as painted),

each control first clamped to its range (:data:`CONTROL_RANGES`), the edited parameter then to the skin model's
domain (exporters.constants.PARAM_RANGES).  The edited tone's answer (:func:`edited_records`):

* colour: the painted colour carried by the edit's change of the model's colour, per linear-sRGB channel
  c' = clip(c x C(e(Enc(c))) / C(Enc(c)), 0, 1), C = D65 linear sRGB of the decoder's reflectance.  It equals the
  skin model's answer exposure(c) x C(e(Enc(c))) up to the inversion's own reproduction of c (ΔE76 0.03-0.24 on
  skin), and it is exactly c at neutral, so a masked edit has no seam;
* media: the decoder's K spectral media of the edited tone, collapsed to Cycles media that render c'
  (exporters.collapse with the painted colour c'; with the model's colour, to the decoder's reflectance).

Neutral rows (m = 1, b = 1, o = 0) are today's records bit for bit: callers route them to
exporters.texel_records.exact_records (:func:`neutral_rows`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import collapse, inference, texel_records
from .constants import PARAM_NAMES, PARAM_RANGES
from .texel_records import CollapseOptions

#: Names of the controls, in the order of an edit row (N, 3).
CONTROLS: tuple[str, ...] = ("melanin", "blood", "oxygenation")
#: The controls' values that leave the tone as painted.
NEUTRAL: tuple[float, float, float] = (1.0, 1.0, 0.0)
#: Range of each control (values outside are clamped): the multipliers span 1/4 to 4 (skin's melanin varies about
#: 50-fold between people and a tan raises it 2-3-fold; blood doubles in a flush and halves in pallor), the
#: oxygenation shift spans the skin model's whole so2 domain (0.5-1.0).
CONTROL_RANGES: dict[str, tuple[float, float]] = {"melanin": (0.25, 4.0), "blood": (0.25, 4.0),
                                                  "oxygenation": (-0.5, 0.5)}
#: Which biophysical parameter (index into exporters.constants.PARAM_NAMES) each control changes.
PARAMETER_OF: dict[str, int] = {"melanin": PARAM_NAMES.index("f_mel"), "blood": PARAM_NAMES.index("f_blood"),
                                "oxygenation": PARAM_NAMES.index("so2")}
#: File name of the decoder graph, shipped beside the inversion model (docs/contracts.md §3).
DECODER_NAME = "skin_decoder.onnx"


def decoder_beside(model_path: str | os.PathLike) -> Path:
    """The decoder shipped beside the inversion model ``model_path``."""
    return Path(model_path).with_name(DECODER_NAME)


@dataclass(frozen=True)
class SkinEdit:
    """One edit for every texel: ``melanin`` and ``blood`` multipliers, ``oxygenation`` shift."""

    melanin: float = 1.0
    blood: float = 1.0
    oxygenation: float = 0.0

    def __post_init__(self) -> None:
        for name in CONTROLS:
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be a finite number, got {getattr(self, name)}")

    @property
    def neutral(self) -> bool:
        return (self.melanin, self.blood, self.oxygenation) == NEUTRAL

    def row(self) -> np.ndarray:
        """The edit as one row (3,) float64 (melanin, blood, oxygenation)."""
        return np.array([self.melanin, self.blood, self.oxygenation], np.float64)


#: Named starting points of the panel and the API (values of melanin, blood, oxygenation).
PRESETS: dict[str, SkinEdit] = {
    "tan": SkinEdit(melanin=2.0, blood=1.1, oxygenation=0.0),
    "flush": SkinEdit(melanin=1.0, blood=2.5, oxygenation=0.05),
    "pallor": SkinEdit(melanin=1.0, blood=0.4, oxygenation=0.0),
    "cold": SkinEdit(melanin=1.0, blood=0.8, oxygenation=-0.3),
}


def clamp_controls(edits: np.ndarray) -> np.ndarray:
    """Edit rows (N, 3) with each control clamped to CONTROL_RANGES and NaN replaced by the neutral value."""
    e = np.array(edits, np.float64).reshape(-1, 3)
    for j, name in enumerate(CONTROLS):
        lo, hi = CONTROL_RANGES[name]
        e[:, j] = np.clip(np.nan_to_num(e[:, j], nan=NEUTRAL[j], posinf=hi, neginf=lo), lo, hi)
    return e


def neutral_rows(edits: np.ndarray) -> np.ndarray:
    """(N,) bool: rows whose edit, once clamped, leaves the tone as painted."""
    return np.all(clamp_controls(edits) == np.array(NEUTRAL), axis=1)


def apply_edit(biophysical: np.ndarray, edits: np.ndarray) -> np.ndarray:
    """The edited tones (N, 5): f_mel x melanin, f_blood x blood, so2 + oxygenation (controls clamped to
    CONTROL_RANGES), each parameter clamped to the skin model's domain.  ``edits`` (N, 3) or (3,)."""
    bio = np.array(biophysical, np.float64).reshape(-1, 5)
    e = np.broadcast_to(clamp_controls(edits), (len(bio), 3)) if np.size(edits) == 3 else clamp_controls(edits)
    out = bio.copy()
    out[:, PARAMETER_OF["melanin"]] *= e[:, 0]
    out[:, PARAMETER_OF["blood"]] *= e[:, 1]
    out[:, PARAMETER_OF["oxygenation"]] += e[:, 2]
    for j in PARAMETER_OF.values():
        lo, hi = PARAM_RANGES[PARAM_NAMES[j]]
        out[:, j] = np.clip(out[:, j], lo, hi)
    return out


def model_colour(reflectance: np.ndarray) -> np.ndarray:
    """C (N, 3): D65 linear sRGB of reflectance spectra (N, 376) (exporters.collapse.channel_matrix)."""
    return np.asarray(reflectance, np.float64) @ collapse.channel_matrix().T


def colour_ratio(before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """Per-channel factor (N, 3) the edit applies to the painted colour: C_after / C_before (1 where C_before is
    not positive)."""
    ok = before > 1e-9
    return np.where(ok, after / np.where(ok, before, 1.0), 1.0)


def edited_tones(model: inference.InversionSession, rgb: np.ndarray, edits: np.ndarray,
                 decoder: str | os.PathLike) -> dict[str, np.ndarray]:
    """The network and the decoder on painted rows ``rgb`` (N, 3) with ``edits`` (N, 3): ``biophysical`` (N, 5) as
    inverted, ``edited`` (N, 5), ``exposure`` (N,), ``ratio`` (N, 3) (:func:`colour_ratio`), ``colour`` (N, 3) the
    edited painted colour c', ``reference`` (N, 3) the skin model's colour exposure x C(edited tone), and the
    decoder's outputs for the edited tone (``reflectance``, ``alpha``, ``sigma_t``, ``g``, ``weight``)."""
    x = np.asarray(rgb, np.float32).reshape(-1, 3)
    return tones_of(model.run(x), x, edits, decoder)


def tones_of(out: dict[str, np.ndarray], rgb: np.ndarray, edits: np.ndarray,
             decoder: str | os.PathLike) -> dict[str, np.ndarray]:
    """:func:`edited_tones` from the network's outputs ``out`` on painted rows ``rgb`` (N, 3)."""
    x = np.asarray(rgb, np.float32).reshape(-1, 3)
    bio = out["biophysical"].astype(np.float64)
    edited = apply_edit(bio, edits)
    dec = inference.run_decoder(edited, decoder)
    before, after = model_colour(out["reflectance"]), model_colour(dec["reflectance"])
    ratio = colour_ratio(before, after)
    exposure = out["exposure"][:, 0].astype(np.float64)
    painted = np.clip(x.astype(np.float64), 0.0, 1.0)
    return {"biophysical": bio, "edited": edited, "exposure": exposure, "ratio": ratio,
            "colour": np.clip(painted * ratio, 0.0, 1.0), "reference": exposure[:, None] * after, **dec}


def edited_records(model: inference.InversionSession, rgb: np.ndarray, edits: np.ndarray,
                   targets: tuple[str, ...], options: CollapseOptions,
                   decoder: str | os.PathLike) -> dict[str, np.ndarray]:
    """Records (exporters.texel_records) of painted rows ``rgb`` (N, 3) under ``edits`` (N, 3), exactly: the edited
    tone's decoder media collapsed to the edited colour (module docstring).  ``biophysical`` holds the edited
    tone; ``exposure`` the painted colour's."""
    tone = edited_tones(model, rgb, edits, decoder)
    outputs = {"biophysical": tone["edited"].astype(np.float32), "exposure": tone["exposure"][:, None],
               **{n: tone[n] for n in ("reflectance", "alpha", "sigma_t", "g", "weight")}}
    painted = tone["colour"] if options.painted else None
    return texel_records.records_of(outputs, painted, targets, options)
