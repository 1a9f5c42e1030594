"""Monte Carlo photon transport in layered media and the homogeneous lookup tables (paper §3, §4.2).

Modules: ``medium`` (the layered medium), ``physics`` (Fresnel, Henyey-Greenstein, direction frames),
``walker`` (the one vectorised packet walker), ``transport`` (``simulate``: tallies), ``lut`` (the
R(albedo, g), P(r | albedo, g) tables by absorption reweighting), ``cli_*`` (commands), ``bench``.
"""
