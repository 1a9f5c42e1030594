"""The illuminations of the walk: a diffuse (cosine-weighted) lobe, a normal collimated beam, or a collimated beam at
a polar angle, parsed from the text the command line and the Python API take.  Torch-free.

"collimated:THETA" (THETA in degrees, 0 <= THETA < 90) is a pencil beam in air hitting the origin at polar angle
THETA, in the x-z plane, travelling towards +x: it is refracted into the medium (Snell) and loses its unpolarised
Fresnel reflectance as specular light.  The plane of incidence is therefore the x-z plane, and light that exits
at x > 0 went forward.  "collimated:0" is the "normal" beam itself (the same packets bit for bit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: The largest polar angle of a collimated beam, degrees (90 would be a beam that never enters).
MAX_THETA_DEG = 89.9


@dataclass(frozen=True)
class Illumination:
    """kind "diffuse" or "collimated"; theta_deg the collimated beam's polar angle in air (0: normal)."""

    kind: str
    theta_deg: float = 0.0

    @property
    def diffuse(self) -> bool:
        return self.kind == "diffuse"

    @property
    def cos_in(self) -> float:
        """Cosine of the beam's polar angle in air (1.0 exactly for normal incidence and for diffuse light)."""
        return 1.0 if self.diffuse or self.theta_deg == 0.0 else math.cos(math.radians(self.theta_deg))

    @property
    def name(self) -> str:
        if self.diffuse:
            return "diffuse"
        return "normal" if self.theta_deg == 0.0 else f"collimated:{self.theta_deg:g}"


def parse_illumination(text: str) -> Illumination:
    """``"diffuse"``, ``"normal"`` or ``"collimated:THETA"`` (degrees in [0, MAX_THETA_DEG]) as an Illumination;
    ValueError naming the accepted forms otherwise."""
    if text == "diffuse":
        return Illumination("diffuse")
    if text == "normal":
        return Illumination("collimated", 0.0)
    head, _, value = str(text).partition(":")
    if head == "collimated" and value:
        try:
            theta = float(value)
        except ValueError:
            theta = math.nan
        if math.isfinite(theta) and 0.0 <= theta <= MAX_THETA_DEG:
            return Illumination("collimated", theta)
    raise ValueError(f"illumination must be 'diffuse', 'normal' or 'collimated:THETA' with THETA in degrees in "
                     f"[0, {MAX_THETA_DEG:g}], got {text!r}")
