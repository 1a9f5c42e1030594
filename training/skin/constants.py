"""Physical constants of the skin model, each with its source (see training/skin/README.md).

Units: lambda in nm; absorption and scattering coefficients in cm^-1; concentrations in g/L;
molar masses in g/mol.  Decadic molar extinction eps [cm^-1 M^-1] -> mu_a = ln(10) * eps * C[mol/L].
"""

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

# --- Bloodless-tissue baseline (Jacques 1998, OMLC; Donner & Jensen 2006 in mm^-1) ----------------
# mu_a,base = 0.244 + 85.3 * exp(-(lambda - 154) / 66.2) cm^-1.  A fit for 350-1100 nm, extrapolated
# below 350 nm (as every skin model on this grid does).
BASELINE_OFFSET = 0.244
BASELINE_AMPLITUDE = 85.3
BASELINE_CENTRE_NM = 154.0
BASELINE_WIDTH_NM = 66.2

# --- Basal chromophores (fixed for every tone) -----------------------------------------------------
BILIRUBIN_MOLAR_MASS = 584.66  # g/mol (PhotochemCAD)
# Bilirubin is a plasma pigment: 0.05 g/L of whole blood (BioSpec basal value, Krishnaswamy &
# Baranoski 2004), scaled by the blood fraction f_blood -- our choice, see README.
BILIRUBIN_G_PER_L_BLOOD = 0.05
BETA_CAROTENE_MOLAR_MASS = 536.87  # g/mol (PhotochemCAD)
# beta-carotene basal concentrations (BioSpec lineage, Krishnaswamy & Baranoski 2004):
BETA_CAROTENE_G_PER_L_EPIDERMIS = 2.1e-4
BETA_CAROTENE_G_PER_L_DERMIS = 7.0e-5
# Water volume fraction of the bloodless dermis (Jacques 2013, PMB 58:R37, Table 3: ~0.65 for dermis).
DERMIS_WATER_FRACTION = 0.65

# --- Scattering: Jacques 1998 (OMLC skin optics summary), Mie + Rayleigh reduced scattering ---------
# mu_s' = 2e5 * lambda^-1.5 + 2e12 * lambda^-4 cm^-1 (49.9 cm^-1 at 500 nm).  Used for both layers.
MIE_SCALE = 2.0e5
MIE_EXPONENT = 1.5
RAYLEIGH_SCALE = 2.0e12
RAYLEIGH_EXPONENT = 4.0
