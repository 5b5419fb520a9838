"""The acoustic channel's link budget, after DESERT's UW/PHYSICAL (an SNR-threshold model).

DESERT computes, per packet, the received power P / A(l, f) and the ambient noise power
N(f) * bandwidth, and drops the packet when the SNR is below its acquisition threshold
(then draws bit errors from the modulation's BER).  This module holds that physics as
pure functions of plain numbers, so it can be tested against hand-computed values:

- transmission loss A(l, f) in dB: practical spreading k * 10 log10(l / 1 m) plus Thorp's
  absorption a(f) (dB/km, f in kHz) times l in km;
- ambient noise PSD (Wenz curves in the parametrisation used by Stojanovic and by DESERT):
  turbulence, shipping (activity 0..1), wind (m/s) and thermal noise, in dB re 1 uPa^2/Hz,
  summed in linear power and integrated over the signal band;
- SNR = source level - A(l, f) - noise power in the band, all in dB.

`SnrModel` bundles the parameters; its defaults are calibrated (see docs/emulator.md) so
the delivery ratio against distance has the shape of the rmw_desert thesis' chapter 7
figures: full delivery to about 7 km with no wind, 5 km at 5 m/s and 4 km at 10 m/s, then
a fall to zero within about a kilometre.  The per-packet randomness that makes the
fall-off steep but not a step is log-normal fading (`fading_db`, a Gaussian in dB).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

_NOISE_BAND_POINTS = 64  # midpoint rule over the band: plenty for PSDs this smooth


def thorp_db_per_km(f_khz: float) -> float:
    """Thorp's absorption coefficient in dB/km for a frequency in kHz (with its low-f form)."""
    f2 = f_khz * f_khz
    if f_khz >= 0.4:
        return 0.11 * f2 / (1 + f2) + 44 * f2 / (4100 + f2) + 2.75e-4 * f2 + 0.003
    return 0.002 + 0.11 * f2 / (1 + f2) + 0.011 * f2


def transmission_loss_db(distance_m: float, f_khz: float, spreading: float = 1.5) -> float:
    """Spreading plus absorption loss in dB over `distance_m` (distances under 1 m count as 1 m)."""
    d = max(distance_m, 1.0)
    return spreading * 10 * math.log10(d) + (d / 1000.0) * thorp_db_per_km(f_khz)


def noise_components_db(f_khz: float, wind: float = 0.0, shipping: float = 0.5) -> dict[str, float]:
    """The four Wenz noise PSDs at `f_khz`, in dB re 1 uPa^2/Hz (for inspection and tests)."""
    if f_khz <= 0:
        raise ValueError(f"noise frequency must be positive, got {f_khz} kHz")
    if not 0.0 <= shipping <= 1.0:
        raise ValueError(f"shipping activity must be in [0, 1], got {shipping}")
    if wind < 0:
        raise ValueError(f"wind speed must be >= 0 m/s, got {wind}")
    lf = math.log10(f_khz)
    return {
        "turbulence": 17 - 30 * lf,
        "shipping": 40 + 20 * (shipping - 0.5) + 26 * lf - 60 * math.log10(f_khz + 0.03),
        "wind": 50 + 7.5 * math.sqrt(wind) + 20 * lf - 40 * math.log10(f_khz + 0.4),
        "thermal": -15 + 20 * lf,
    }


def noise_psd_db(f_khz: float, wind: float = 0.0, shipping: float = 0.5) -> float:
    """Total ambient noise PSD at `f_khz` in dB re 1 uPa^2/Hz: the four sources summed in power."""
    parts = noise_components_db(f_khz, wind, shipping)
    return 10 * math.log10(sum(10 ** (v / 10) for v in parts.values()))


def noise_power_db(center_hz: float, bandwidth_hz: float, wind: float = 0.0,
                   shipping: float = 0.5) -> float:
    """Noise power in the band [center - bw/2, center + bw/2], in dB re 1 uPa^2."""
    if bandwidth_hz <= 0 or bandwidth_hz >= 2 * center_hz:
        raise ValueError(f"bandwidth {bandwidth_hz} Hz does not fit around {center_hz} Hz")
    step = bandwidth_hz / _NOISE_BAND_POINTS
    low = center_hz - bandwidth_hz / 2
    total = 0.0
    for i in range(_NOISE_BAND_POINTS):
        f_khz = (low + (i + 0.5) * step) / 1000.0
        total += 10 ** (noise_psd_db(f_khz, wind, shipping) / 10) * step
    return 10 * math.log10(total)


def bpsk_per(snr_linear: float, nbits: int) -> float:
    """Packet error rate of `nbits` bits sent with BPSK at this (linear) SNR, as DESERT draws it."""
    if snr_linear <= 0:
        return 1.0
    ber = 0.5 * math.erfc(math.sqrt(snr_linear))
    return 1.0 - (1.0 - ber) ** nbits


@dataclass(frozen=True)
class SnrModel:
    """Parameters of the SNR-threshold channel; defaults calibrated to the thesis (chapter 7).

    tx_power_db:  source level in dB re 1 uPa @ 1 m (DESERT's TxPower_ in dB).  Calibrated:
                  174.5 dB puts the end of loss-free delivery at ~7 km with no wind.
    threshold_db: acquisition threshold (DESERT's AcquisitionThreshold_dB_; 10 dB in its samples).
    fading_db:    standard deviation of the per-packet log-normal fading, in dB.
    """

    wind: float = 0.0              # m/s
    shipping: float = 0.5          # shipping activity, 0 (none) .. 1 (heavy)
    frequency: float = 25000.0     # carrier, Hz
    bandwidth: float = 5000.0      # Hz
    spreading: float = 1.5         # practical spreading exponent k
    tx_power_db: float = 174.5
    threshold_db: float = 10.0
    fading_db: float = 1.5
    bpsk_errors: bool = True       # also draw BPSK bit errors on the (faded) SNR, as DESERT does

    def __post_init__(self) -> None:
        # Validate once, here, so a bad scenario fails at load and not on the first packet.
        noise_power_db(self.frequency, self.bandwidth, self.wind, self.shipping)
        if self.spreading <= 0:
            raise ValueError(f"spreading exponent must be > 0, got {self.spreading}")
        if self.fading_db < 0:
            raise ValueError(f"fading_db must be >= 0, got {self.fading_db}")

    def noise_db(self) -> float:
        """Noise power in the signal band, dB re 1 uPa^2."""
        return noise_power_db(self.frequency, self.bandwidth, self.wind, self.shipping)

    def received_db(self, distance_m: float) -> float:
        """Mean received level in dB re 1 uPa at `distance_m`."""
        return self.tx_power_db - transmission_loss_db(distance_m, self.frequency / 1000.0,
                                                       self.spreading)

    def snr_db(self, distance_m: float) -> float:
        """Mean SNR in dB at `distance_m` (before fading)."""
        return self.received_db(distance_m) - self.noise_db()


# -- named PHYs ---------------------------------------------------------------------------

# DESERT's stock two-node scenario, the one the calibration traces were measured on
# (/work/shared/calibration README: UW/PHYSICAL, 25 kHz, 5 kHz, 4800 bit/s, acquisition
# threshold 5 dB, 150 dB source level, practical spreading 1.75, wind 0, shipping 0.5, no
# fading). One-way delivery falls through 0.9 at 3.4 km and ends near 3.8 km, as on DESERT.
DESERT_STOCK = SnrModel(wind=0.0, shipping=0.5, frequency=25000.0, bandwidth=5000.0,
                        spreading=1.75, tx_power_db=150.0, threshold_db=5.0, fading_db=0.0)

# By name (`uwgen emulate --phy NAME`, `uwgen demo --phy NAME`): the stock scenario's (the
# default), the thesis-calibrated one (chapter 7: full delivery to ~7 km with no wind), and
# none (no SNR losses: only collisions and a fixed packet error rate).
PHYS: dict[str, SnrModel | None] = {
    "desert-stock": DESERT_STOCK,
    "thesis": SnrModel(),
    "none": None,
}
DEFAULT_PHY = "desert-stock"


def phy(name: str) -> SnrModel | None:
    """The SnrModel named `name` (None for "none"); KeyError names the known ones."""
    try:
        return PHYS[name]
    except KeyError:
        raise KeyError(f"no PHY named {name!r} (known: {', '.join(PHYS)})") from None


def locked_outcome(snr, nbits: int, snr_db: float, interference: float, noise: float,
                   rng) -> str | None:
    """Outcome of a packet a receiver stayed locked on to its end (the emulator core's): None
    (received), "snr" (bit errors of the noise) or "collision" (of noise plus the MEANPOWER
    interference of the packets that overlapped it). `snr`: the scenario's SnrModel (None:
    any overlap is a collision); `noise`: the noise power, linear; `rng`: the bit-error draws."""
    if snr is None:
        return "collision" if interference > 0 else None
    u = rng.random() if snr.bpsk_errors else 1.0
    snr_lin = 10 ** (snr_db / 10)
    if snr.bpsk_errors and u < bpsk_per(snr_lin, nbits):
        return "snr"
    if interference > 0:
        # DESERT draws the bit errors of noise plus interference with the same number;
        # without bit errors, a SINR under the threshold is a collision.
        signal = snr_lin * noise
        sinr = signal / (noise + interference)
        if snr.bpsk_errors:
            if u < bpsk_per(sinr, nbits):
                return "collision"
        elif 10 * math.log10(sinr) < snr.threshold_db:
            return "collision"
    return None
