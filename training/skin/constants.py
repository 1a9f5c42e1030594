"""Physical constants of the skin model, each with its source (see training/skin/README.md).

The choices that measured skin decided between (scattering law, bloodless baseline) are named
:class:`SkinModelSpec` instances: ``SKIN_MODEL`` is the model every part uses; the others are the
candidates compared against the NIST measurements (``python -m training realskin --study``).

Units: lambda in nm; absorption and scattering coefficients in cm^-1; concentrations in g/L;
molar masses in g/mol.  Decadic molar extinction eps [cm^-1 M^-1] -> mu_a = ln(10) * eps * C[mol/L].
"""

from dataclasses import dataclass

# --- Haemoglobin (Prahl, OMLC compilation of Gratzer & Kollias) -----------------------------------
HB_CONCENTRATION_G_PER_L = 150.0  # haemoglobin in whole blood (Prahl, OMLC "Optical absorption of hemoglobin")
HB_MOLAR_MASS = 64500.0  # g/mol, haemoglobin tetramer (Prahl, OMLC)

# --- Melanin (power laws, valid at every wavelength of the grid) -----------------------------------
# Eumelanin: mu_a = 6.6e11 * lambda^-3.33 cm^-1 (Jacques 1998, OMLC skin optics summary, melanosome;
# used as sigma_a,em by Donner & Jensen 2006).
EUMELANIN_SCALE = 6.6e11
EUMELANIN_EXPONENT = 3.33
# Pheomelanin: mu_a = 2.9e15 * lambda^-4.75 cm^-1 (Donner & Jensen 2006, 2.9e14 mm^-1).
PHEOMELANIN_SCALE = 2.9e15
PHEOMELANIN_EXPONENT = 4.75


# --- Basal chromophores (fixed for every tone) -----------------------------------------------------
BILIRUBIN_MOLAR_MASS = 584.66  # g/mol (PhotochemCAD)
# Bilirubin is a plasma pigment: 0.05 g/L of whole blood (BioSpec basal value, Krishnaswamy &
# Baranoski 2004), scaled by the blood fraction f_blood -- our choice, see training/skin/README.md.
BILIRUBIN_G_PER_L_BLOOD = 0.05
BETA_CAROTENE_MOLAR_MASS = 536.87  # g/mol (PhotochemCAD)
# beta-carotene basal concentrations (BioSpec lineage, Krishnaswamy & Baranoski 2004):
BETA_CAROTENE_G_PER_L_EPIDERMIS = 2.1e-4
BETA_CAROTENE_G_PER_L_DERMIS = 7.0e-5
# Water volume fraction of the bloodless dermis: Jacques 2013 (PMB 58:R37) Table 3 lists 0.65 for dermis.
DERMIS_WATER_FRACTION = 0.65


# --- Scattering laws and bloodless baselines: the choices measured skin decides ----------------------


@dataclass(frozen=True)
class ReducedScattering:
    """mu_s'(lambda) = a_500 [f_ray (lambda/500)^-4 + (1 - f_ray) (lambda/500)^-b_mie] cm^-1.

    The form of Jacques 2013 (PMB 58:R37) eq. 2; f_ray = 0 gives eq. 1, a (lambda/500)^-b.
    """

    a_500: float  # cm^-1 at 500 nm
    f_ray: float  # Rayleigh share at 500 nm
    b_mie: float  # Mie exponent
    source: str


@dataclass(frozen=True)
class Baseline:
    """Bloodless-tissue absorption mu_a = offset + amplitude exp(-(lambda - centre_nm) / width_nm), cm^-1."""

    offset: float
    amplitude: float
    centre_nm: float
    width_nm: float
    source: str


@dataclass(frozen=True)
class SkinModelSpec:
    """The literature choices of one version of the skin model (both layers scatter alike)."""

    name: str
    scattering: ReducedScattering
    baseline: Baseline
    dermis_water_fraction: float = DERMIS_WATER_FRACTION


# Jacques 1998 (OMLC skin optics summary): mu_s' = 2e5 lambda^-1.5 + 2e12 lambda^-4 cm^-1, i.e. 49.9 cm^-1
# at 500 nm of which 2e12/500^4 = 32.0 Rayleigh and 2e5/500^1.5 = 17.9 Mie, Mie exponent 1.5.
JACQUES_1998_SCATTERING = ReducedScattering(
    a_500=2e12 / 500.0**4 + 2e5 / 500.0**1.5, f_ray=(2e12 / 500.0**4) / (2e12 / 500.0**4 + 2e5 / 500.0**1.5),
    b_mie=1.5, source="Jacques 1998, OMLC skin optics summary (dermis, Mie + Rayleigh)")
# Bloodless baseline, Jacques 1998 (OMLC; Donner & Jensen 2006 in mm^-1): 0.244 + 85.3 exp(-(l - 154)/66.2)
# cm^-1.  A fit for 350-1100 nm to bloodless rat skin, extrapolated below 350 nm.
JACQUES_1998_BASELINE = Baseline(offset=0.244, amplitude=85.3, centre_nm=154.0, width_nm=66.2,
                                 source="Jacques 1998, OMLC skin optics summary (bloodless rat skin)")

# Jacques 2013 (PMB 58:R37) Table 2, "skin" (average of 8 studies): mu_s' = 46.0 (lambda/500)^-1.421 cm^-1
# (eq. 1; a = 46.0 +- 13.7 cm^-1, b = 1.421 +- 0.517).  Twice Jacques 1998 in the NIR (21.6 vs 11.9 cm^-1 at 850 nm).
JACQUES_2013_SKIN_SCATTERING = ReducedScattering(a_500=46.0, f_ray=0.0, b_mie=1.421,
                                                 source="Jacques 2013, PMB 58:R37, Table 2 (skin, eq. 1)")
# Jacques 2013 Table 1, dermis of Salomatina et al. 2006 (ex vivo): a' = 43.6, f_Ray = 0.41, b_Mie = 0.562.
SALOMATINA_DERMIS_SCATTERING = ReducedScattering(a_500=43.6, f_ray=0.41, b_mie=0.562,
                                                 source="Salomatina 2006 dermis, Jacques 2013 Table 1 (eq. 2)")
# Jacques 2013 Table 1, skin of Bashkatov et al. (in vitro): a' = 36.4, f_Ray = 0.48, b_Mie = 0.22
# (= 1.1e12 lambda^-4 + 73.7 lambda^-0.22 cm^-1).
BASHKATOV_SCATTERING = ReducedScattering(a_500=36.4, f_ray=0.48, b_mie=0.22,
                                         source="Bashkatov 2011 skin, Jacques 2013 Table 1 (eq. 2)")

#: The model before it was checked against measured skin (Jacques 1998 scattering and baseline).
JACQUES_1998 = SkinModelSpec("jacques1998", JACQUES_1998_SCATTERING, JACQUES_1998_BASELINE)
# Bloodless baseline of the adopted model: Jacques 1998's exponential (the UV-blue rise of bloodless tissue) with
# its NIR offset 0.244 cm^-1 halved to 0.12 cm^-1.  The offset comes from in vitro rat skin (Huang & Jacques,
# unpublished; OMLC 1998 page); Jacques 2013 (PMB 58:R37, eq. 12) composes skin absorption from blood, water, fat
# and melanin with no such offset, and in vivo human dermis absorbs 0.035-0.05 cm^-1 in all at 850 nm (Fredriksson
# et al. 2023, JBO 28:115001).  Within that bracket [0, 0.244] the offset was calibrated against the NIST odd
# subjects (training.realskin; 0.09/0.122/0.15 cm^-1 gave mean RMSE 0.0139/0.0129/0.0136), see training/skin/README.md.
CALIBRATED_BASELINE = Baseline(offset=0.12, amplitude=85.3, centre_nm=154.0, width_nm=66.2,
                               source="Jacques 1998 exponential, NIR offset 0.12 cm^-1 calibrated on NIST odd subjects")

#: The model every part of the project uses: Jacques 2013 skin scattering, calibrated bloodless baseline.
SKIN_MODEL = SkinModelSpec("jacques2013_nist", JACQUES_2013_SKIN_SCATTERING, CALIBRATED_BASELINE)
