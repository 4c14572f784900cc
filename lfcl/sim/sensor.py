"""The image sensor: lux -> electrons -> noisy digital numbers, as ISET models it.

Defaults follow the paper's camera (section 2.2: 1.7 um pixels, 1/90 s) and
typical values for a small-pixel CMOS sensor:

==========================  ==========  ==============================================
constant                    default     meaning
==========================  ==========  ==============================================
pixel_size_um               1.7         pixel pitch (square), um
exposure_s                  1/90        exposure time, s
wavelength_nm               555         photometric conversion wavelength (V peak)
quantum_efficiency          0.6         electrons per photon absorbed
cfa_transmittance           0.8         colour-filter in-band transmittance (R = G = B)
full_well_e                 6000        full-well capacity, e- (saturation)
read_noise_e                2.5         read noise, e- rms (Gaussian)
dark_current_e_per_s        5.0         dark current, e-/s (Poisson, 0.056 e- at 1/90 s)
adc_bits                    12          ADC resolution; white level = 2**bits - 1 = 4095
black_level_dn              64          black level (offset), DN
==========================  ==========  ==============================================

Lux to electrons. Illuminance ``E`` (lux) at the sensor is taken as light at
555 nm, where 1 lux = 1/683 W/m^2. A photon there carries
``h c / 555 nm = 3.579e-19 J``, so 1 lux is ``4.091e15`` photons / (m^2 s). A
1.7 um pixel (2.89e-12 m^2) during 1/90 s then collects ``131.4`` photons per
lux; times QE 0.6 and filter transmittance 0.8: **63.05 electrons per lux per
pixel**. Scene values are linear camera RGB in *lux-equivalents* (a neutral grey
of E lux gives E lux in each of R, G, B), so channel ``c`` of a pixel collects
``63.05 * E_c`` electrons on average. At the default 12 lux mean: 756.6 e-.

Noise, per pixel (ISET's sensorCompute order):

    e  = Poisson(expected_e + dark_current * exposure)      shot + dark-current shot noise
    e += Normal(0, read_noise_e)                            read noise
    e  = min(e, full_well_e)                                full-well saturation
    DN = clip(round(black + e * (white - black) / full_well_e), 0, white)

so the full well maps to the white level (0.672 DN per e- at the defaults).
In normalised units ``x = (DN - black) / (white - black) = e / full_well``
the variance is ``S * x + O`` with ``S = 1 / full_well`` and
``O = (read_noise / full_well)^2 + 1 / (12 (white - black)^2)`` (quantisation):
the DNG NoiseProfile the simulator writes.
"""

from __future__ import annotations

import dataclasses

import numpy as np

PLANCK = 6.62607015e-34  # J s
LIGHT_SPEED = 299_792_458.0  # m / s
LUMINOUS_EFFICACY = 683.0  # lm / W at 555 nm


@dataclasses.dataclass(frozen=True)
class SensorModel:
    """A photon-counting sensor with shot, read and dark-current noise and an ADC (see module docstring)."""

    pixel_size_um: float = 1.7
    exposure_s: float = 1.0 / 90.0
    wavelength_nm: float = 555.0
    quantum_efficiency: float = 0.6
    cfa_transmittance: float = 0.8
    full_well_e: float = 6000.0
    read_noise_e: float = 2.5
    dark_current_e_per_s: float = 5.0
    adc_bits: int = 12
    black_level_dn: int = 64

    def __post_init__(self):
        for name in ("pixel_size_um", "exposure_s", "wavelength_nm", "quantum_efficiency",
                     "cfa_transmittance", "full_well_e"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"sensor {name} must be positive, got {value!r}")
        for name in ("read_noise_e", "dark_current_e_per_s"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"sensor {name} must be >= 0, got {value!r}")
        if self.quantum_efficiency > 1 or self.cfa_transmittance > 1:
            raise ValueError("sensor quantum_efficiency and cfa_transmittance must be at most 1")
        if not 8 <= int(self.adc_bits) <= 16:
            raise ValueError(f"sensor adc_bits must be 8..16, got {self.adc_bits!r}")
        if not 0 <= int(self.black_level_dn) < self.white_level_dn // 2:
            raise ValueError(f"sensor black_level_dn must be in [0, white/2), got {self.black_level_dn!r}")

    # --- photometry -------------------------------------------------------
    @property
    def photon_energy_j(self) -> float:
        return PLANCK * LIGHT_SPEED / (self.wavelength_nm * 1e-9)

    @property
    def pixel_area_m2(self) -> float:
        return (self.pixel_size_um * 1e-6) ** 2

    @property
    def photons_per_lux(self) -> float:
        """Photons reaching one pixel during one exposure per lux of illuminance."""
        return (1.0 / LUMINOUS_EFFICACY) / self.photon_energy_j * self.pixel_area_m2 * self.exposure_s

    @property
    def electrons_per_lux(self) -> float:
        """Expected photo-electrons per pixel per exposure per lux (in the pixel's colour channel)."""
        return self.photons_per_lux * self.quantum_efficiency * self.cfa_transmittance

    @property
    def dark_electrons(self) -> float:
        return self.dark_current_e_per_s * self.exposure_s

    # --- digitisation -----------------------------------------------------
    @property
    def white_level_dn(self) -> int:
        return 2 ** int(self.adc_bits) - 1

    @property
    def dn_per_electron(self) -> float:
        return (self.white_level_dn - self.black_level_dn) / self.full_well_e

    def lux_to_normalised(self, lux):
        """Lux-equivalent signal -> expected electrons / full well (the normalised raw scale)."""
        return np.asarray(lux) * (self.electrons_per_lux / self.full_well_e)

    def noise_profile(self) -> tuple[float, float]:
        """DNG NoiseProfile ``(S, O)``: variance of the normalised signal x is ``S * x + O``."""
        span = self.white_level_dn - self.black_level_dn
        return 1.0 / self.full_well_e, (self.read_noise_e / self.full_well_e) ** 2 + 1.0 / (12.0 * span**2)

    def noise_sigma(self, x):
        """Noise standard deviation (normalised units) at normalised signal ``x``."""
        s, o = self.noise_profile()
        return np.sqrt(s * np.asarray(x, dtype=np.float64) + o)

    def expose(self, radiance_normalised: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Noisy uint16 DN from the expected signal in normalised units (expected e- / full well).

        ``radiance_normalised`` is per sensor pixel (already CFA-sampled and
        vignetted), any shape.
        """
        expected = np.clip(np.asarray(radiance_normalised, dtype=np.float64), 0.0, None) * self.full_well_e
        expected += self.dark_electrons
        electrons = rng.poisson(expected).astype(np.float64)
        del expected
        electrons += rng.normal(0.0, self.read_noise_e, electrons.shape)
        np.minimum(electrons, self.full_well_e, out=electrons)
        dn = np.rint(self.black_level_dn + electrons * self.dn_per_electron)
        return np.clip(dn, 0, self.white_level_dn).astype(np.uint16)

    def as_meta(self) -> dict:
        fields = dataclasses.asdict(self)
        s, o = self.noise_profile()
        fields.update(
            white_level_dn=self.white_level_dn,
            dn_per_electron=self.dn_per_electron,
            photon_energy_j=self.photon_energy_j,
            photons_per_lux=self.photons_per_lux,
            electrons_per_lux=self.electrons_per_lux,
            dark_electrons=self.dark_electrons,
            noise_profile={"S": s, "O": o, "variance": "S * x + O, x = (DN - black) / (white - black)"},
        )
        return fields
