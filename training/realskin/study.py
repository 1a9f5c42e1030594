"""The cause study: which modelling choice makes the skin model darker than measured skin.

    python -m training realskin --study [--out DIR] [--photons 3000]

Each candidate is one change to the model, or to how it is compared with the measurement, fitted to every
measured subject like the main run (Monte Carlo only).  The table gives the mean spectral RMSE at
exposure 1, the free-exposure factors and how often a fitted parameter sits at an edge of its range.
The candidates and their sources are in ``CANDIDATES``; the findings are written up in
training/skin/README.md.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from exporters.constants import WAVELENGTHS_NM
from training.realskin.fit import at_edge, fit_subjects
from training.realskin.forward import MonteCarloForward, cached_walk
from training.skin import constants as k


@dataclass(frozen=True)
class Candidate:
    """A skin model and a measurement geometry to compare with the data."""

    label: str
    spec: k.SkinModelSpec
    illumination: str = "normal"  # "diffuse": the dataset's cosine-weighted light
    specular: bool = True  # add the rough surface's specular (the measurement includes it)
    port_cm: tuple[float, float] | None = None  # (beam radius, port radius): lateral loss of a small port


def _spec(name: str, scattering: k.ReducedScattering, offset: float | None = None) -> k.SkinModelSpec:
    base = k.JACQUES_1998_BASELINE if offset is None else dataclasses.replace(k.JACQUES_1998_BASELINE, offset=offset)
    return k.SkinModelSpec(name, scattering, base)


CANDIDATES: tuple[Candidate, ...] = (
    Candidate("Jacques 1998 model, dataset geometry (diffuse light, no specular)", k.JACQUES_1998,
              illumination="diffuse", specular=False),
    Candidate("Jacques 1998 model, measurement geometry (normal beam + specular)", k.JACQUES_1998),
    Candidate("scattering: Jacques 2013 skin (Table 2, eq. 1)", _spec("j13", k.JACQUES_2013_SKIN_SCATTERING)),
    Candidate("scattering: Salomatina 2006 dermis (Jacques 2013 Table 1)",
              _spec("salomatina", k.SALOMATINA_DERMIS_SCATTERING)),
    Candidate("scattering: Bashkatov 2011 skin (Jacques 2013 Table 1)", _spec("bashkatov", k.BASHKATOV_SCATTERING)),
    Candidate("Jacques 2013 scattering, no baseline offset (Jacques 2013 eq. 12)",
              _spec("j13_nooffset", k.JACQUES_2013_SKIN_SCATTERING, offset=0.0)),
    Candidate("Jacques 2013 scattering, no offset, lit 5 mm spot in a 5 mm port",
              _spec("j13_nooffset", k.JACQUES_2013_SKIN_SCATTERING, offset=0.0), port_cm=(0.25, 0.25)),
    Candidate("adopted model (SKIN_MODEL)", k.SKIN_MODEL),
)


def _edge_share(p: np.ndarray) -> list[float]:
    """Share of subjects (5,) whose fitted parameter lies at an edge of its range (``at_edge``)."""
    return at_edge(p).mean(0).round(3).tolist()


def run_candidate(c: Candidate, names, measured, channels, photons: int, seed: int, cache: Path | None,
                  device: str = "cpu") -> dict:
    """Fit every subject with candidate ``c``; its row of the study table."""
    traj = cached_walk(channels, photons, seed, cache, device, progress=True, spec=c.spec,
                       illumination=c.illumination)
    fw = MonteCarloForward(traj, specular=None if c.specular else 0.0, spec=c.spec, port_cm=c.port_cm)
    wl = WAVELENGTHS_NM[channels]
    row = {"label": c.label, "model": c.spec.name, "scattering": c.spec.scattering.source,
           "baseline_offset": c.spec.baseline.offset, "illumination": c.illumination, "specular": fw.specular,
           "port_cm": c.port_cm}
    for free in (False, True):
        fits = fit_subjects(fw, names, measured, wl, fw.specular, free, seed=seed)
        p = np.array([f.p for f in fits])
        e = np.array([f.exposure for f in fits])
        row["free" if free else "fixed"] = {
            "rmse_400_1000": round(float(np.mean([f.rmse["400_1000"] for f in fits])), 4),
            "rmse_vis": round(float(np.mean([f.rmse["vis"] for f in fits])), 4),
            "rmse_nir": round(float(np.mean([f.rmse["nir"] for f in fits])), 4),
            "rmse_uv": round(float(np.mean([f.rmse["uv"] for f in fits])), 4),
            "exposure": [round(float(e.min()), 3), round(float(np.median(e)), 3), round(float(e.max()), 3)],
            "p_median": np.median(p, 0).round(4).tolist(), "edge_share": _edge_share(p)}
    return row


def markdown(rows: list[dict]) -> str:
    """The study table."""
    lines = ["| candidate | RMSE 400–1000, exposure 1 | Vis | NIR | exposure free (min / median / max) "
             "| RMSE free | parameters at an edge (f_mel, f_blood, t_epi, so2, b_mel) |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        f, g = r["fixed"], r["free"]
        lines.append(f"| {r['label']} | {f['rmse_400_1000']:.4f} | {f['rmse_vis']:.4f} | {f['rmse_nir']:.4f} "
                     f"| {g['exposure'][0]:.2f} / {g['exposure'][1]:.2f} / {g['exposure'][2]:.2f} "
                     f"| {g['rmse_400_1000']:.4f} | {' '.join(f'{v:.0%}' for v in f['edge_share'])} |")
    return "\n".join(lines) + "\n"


def run_study(names, measured, channels, photons: int, seed: int, cache: Path | None, out: Path | None,
              device: str = "cpu") -> str:
    """Every candidate in turn (walks cached); writes study.json and study.md into ``out``."""
    rows = [run_candidate(c, names, measured, channels, photons, seed, cache, device) for c in CANDIDATES]
    md = markdown(rows)
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out / "study.json").write_text(json.dumps({"photons": photons, "seed": seed, "rows": rows}, indent=1) + "\n")
        (out / "study.md").write_text(md)
    return md
