"""Every supported chip on the emulated bus: its reader under FIFO stress (issue 15), and its
noise against its datasheet (issue 26).

For each chip, a smooth motion is streamed for a simulated time with a FIFO of a few tens of
milliseconds (the ``fifo_capacity`` fault knob), so that it overflows at most drains and the
reader restarts it hundreds of times. The table gives, per chip and seed: the gaps reported,
lost samples reported minus those really missing (0 is exact), and the error of the delivered
samples' times against the emulator's true sample instants (median, 99th percentile, max).
The chips whose FIFO packets carry timestamps (ICM-42688-P, LSM6DSOX) number their samples from
them; the others estimate the loss of each restart from the host clock.

Data: gyrocal's own emulator only (register-level chips of ``drivers/emulated``); the exact
numbering is also checked on an independent packet generator in
``tests/drivers/test_timestamped_fifo_independent.py``.

The noise tables stream each chip at rest through its reader (the emulated sensor as
``--sim`` builds it bar the coloured noise: its chip-table white-noise density, its filter at
the reader's setting) and give (1) the overlapping Allan deviation at 0.1 s and 1 s, read with
``allantools`` (the ``test`` extra) as an independent oracle, over the datasheet's density
``N`` (the IEEE Std 952 / Kalibr convention ``σ_A(τ) = N / √τ``: 1 is right); (2) the noise
per sample at three filter settings against ``N · √(rate · Σh²)``, the white noise of density
``N`` drawn at the filter's rate through the stand-in at the datasheet's bandwidth ``fc`` (its
impulse response ``h``: ``order`` equal bilinear first-order sections, the ICM-42688-P's
second order at reset), against ``N √(2 ENBW)`` with the analog prototype's noise bandwidth
(``π fc / 2`` for one section), and, where the datasheet gives a noise bandwidth (the
ICM-20948's NBW column), against ``N √(2 NBW)``; with the filter's delay (its group delay at DC
plus any pure delay) beside the datasheet's (the MPU-9250's CONFIG table; the LSM6DSOX's phase
delay in AN5192 Table 14 over its frequency; the others give none); (3) at ``--sim``'s rate, the
bandwidth each reader states against the one its emulated chip applies, and the noise per
sample there (:func:`sim_rate_rows`). The accelerometer table takes three settings per chip
(the LSM6DSOX's LPF2 per AN5192 Table 10, the LSM9DS1's anti-aliasing and high-resolution
filters per its CTRL_REG6_XL / CTRL_REG7_XL).
A datasheet's RMS noise (MPU-9250: 0.1 °/s at 92 Hz) reads its density as one-sided,
``σ = N √NBW``: the emulator is √2 above that reading, on the safe side
(:mod:`gyrocal.drivers.emulated.accel` says the same of the accelerometer).

Usage: ``python -m bench chips [--quick]`` (``--quick``: one seed, 5 s instead of three, 10 s;
the noise streams 20 s instead of 120 s).
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from bench.table import print_table
from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.imu_chips import ChipFaults, SensorTruth, make_emulated_imu
from gyrocal.drivers.emulated.motion import FunctionMotion
from gyrocal.drivers.imu import READERS, open_imu
from gyrocal.drivers.imu.chips import RAD_PER_DEG

# model -> (address, odr_hz, FIFO knob in the chip's unit: about 16 samples)
CHIPS = {  # FIFO capacities in samples: 16, 12, 18, 16, 12 (14-byte frames, 3 words a sample)
    "mpu9250": (0x68, 1000.0, 16 * 14),
    "lsm9ds1": (0x6B, 952.0, 12),
    "icm20948": (0x68, 1125.0, 18 * 14),
    "icm42688p": (0x68, 1000.0, 256),
    "lsm6dsox": (0x6A, 1 / (48 * 25e-6), 12 * 3),
}


def _motion() -> FunctionMotion:
    a = 250 * math.pi / 180
    return FunctionMotion(lambda t: a * np.column_stack(
        [np.sin(2 * np.pi * 0.7 * t), np.cos(2 * np.pi * 1.3 * t), np.sin(2 * np.pi * 0.3 * t)]))


def _run(model: str, seed: int, seconds: float) -> list[object]:
    address, odr, cap = CHIPS[model]
    clock = VirtualClock()
    truth = SensorTruth(noise_density_rad_s_sqrt_hz=0.0)
    bus, addr = make_emulated_imu(model, clock, _motion(), truth, address=address, seed=seed,
                                  faults=ChipFaults(fifo_capacity=cap), subsamples=1,
                                  output_filter=False)
    chip = bus.device(addr)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reader = open_imu(model, bus, addr, clock=clock, range_dps=500, odr_hz=odr)
    reader.start()
    rng = np.random.default_rng(seed + 1)
    batches = []
    while clock.monotonic() < seconds:
        clock.sleep(rng.uniform(0.003, 0.02))
        batches.append(reader.read())
    # which chip sample each delivered one is: match by value around the reader's number
    lsb = reader.info.sensitivity_rad_s_per_lsb
    rate = np.concatenate([b.rate for b in batches])
    naive = chip.fifo_enables[0] + 1 + np.concatenate([b.index for b in batches])
    ks = naive.copy()
    for seg in np.split(np.arange(len(ks)), np.flatnonzero(np.diff(naive) != 1) + 1):
        for d in sorted(range(-50, 51), key=abs):
            t = chip.sample_time(naive[seg] + d)
            m = truth.reading(_motion().rate(t), truth.temperature_at(t))
            if np.allclose(rate[seg], np.clip(np.rint(m / lsb), -32768, 32767) * lsb, atol=1e-12):
                ks[seg] += d
                break
    err = np.abs(np.concatenate([b.t for b in batches]) - chip.sample_time(ks))
    last = ks[-1] - chip.fifo_enables[0] - 1
    reported = sum(g.samples for b in batches for g in b.gaps if g.first_index <= last)
    missing = int(last) - len(ks)
    gaps = sum(len(b.gaps) for b in batches)
    return [model, seed, gaps, reported - missing, float(np.median(err) * 1e6),
            float(np.percentile(err, 99) * 1e6), float(err.max() * 1e6)]


# model -> (odr_hz, range_dps, three gyro filter bandwidths the reader offers at that rate,
# the rate the chip filters at); the first bandwidth is the Allan row's
NOISE_SETTINGS: dict[str, tuple[float, float, tuple[float, ...], float]] = {
    "mpu9250": (1000.0, 250.0, (41.0, 184.0, 5.0), 1000.0),  # DLPF at the internal 1 kHz
    "lsm9ds1": (952.0, 245.0, (58.0, 100.0, 33.0), 952.0),  # LPF2 at the output rate
    "icm20948": (1125.0, 250.0, (51.2, 196.6, 5.7), 1125.0),  # DLPF at the internal 1125 Hz
    "icm42688p": (1000.0, 250.0, (125.0, 250.0, 25.0), 1000.0),  # UI filter at the ODR
    # the gyro chain at 833 Hz (AN5192 Table 14): LPF1 off 295.5, FTYPE 100 96.6, 110 25.0 Hz
    "lsm6dsox": (1 / (48 * 25e-6), 250.0, (295.5, 96.6, 25.0), 1 / (48 * 25e-6)),
}


def still_stream(model: str, seconds: float, *, lowpass_hz: float | None = None,
                 seed: int = 0, chip_out: list[object] | None = None
                 ) -> tuple[np.ndarray, float, float | None]:
    """``seconds`` of a chip at rest through its reader at :data:`NOISE_SETTINGS`' rate and
    range and the filter ``lowpass_hz`` (the reader's default when None): the gyro samples
    (N, 3) in rad/s, the rate and the chip's filter cutoff (None: no filter); the emulated
    chip is appended to ``chip_out`` when given."""
    odr, range_dps, _, _ = NOISE_SETTINGS[model]
    clock = VirtualClock()
    bus, addr = make_emulated_imu(model, clock, seed=seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reader = open_imu(model, bus, addr, clock=clock, range_dps=range_dps, odr_hz=odr,
                          lowpass_hz=lowpass_hz)
    reader.start()
    chunks = []
    while clock.monotonic() < seconds:
        clock.sleep(0.02)
        chunks.append(reader.read().rate)
    rate = np.vstack(chunks)[int(0.5 * odr):]  # past the filter's and the reader's start
    if chip_out is not None:
        chip_out.append(bus.device(addr))
    return rate, 1.0 / bus.device(addr).true_period_s, bus.device(addr).cutoff_hz()


def predicted_sigma(density: float, fc: float | None, filter_rate: float, order: int = 1
                    ) -> float:
    """Per-sample σ of white noise of density ``density`` drawn at ``filter_rate`` through
    ``order`` equal bilinear first-order sections, −3 dB together at ``fc``: ``density ·
    √(rate Σh²)``, the impulse response ``h`` in closed form (one section: ``h₀ = b``,
    ``hₙ = b (1 − a)(−a)^(n−1)``, ``Σh² = k / (1 + k)``), convolved ``order`` times."""
    if fc is None:
        return density * math.sqrt(filter_rate)
    k = math.tan(math.pi * fc / filter_rate) / math.sqrt(2.0 ** (1.0 / order) - 1.0)
    b, a = k / (1 + k), (k - 1) / (k + 1)
    one = np.concatenate(([b], b * (1 - a) * (-a) ** np.arange(3999)))
    h = one
    for _ in range(order - 1):
        h = np.convolve(h, one)[:4000]
    return density * math.sqrt(filter_rate * float(np.sum(h * h)))


def analog_enbw_hz(fc: float, order: int) -> float:
    """The noise bandwidth of ``order`` equal analog first-order low-passes, −3 dB together at
    ``fc``: ``f_s √π Γ(n − ½) / (2 Γ(n))``, ``f_s = fc / √(2^(1/n) − 1)`` (``π fc / 2`` for
    one)."""
    fs = fc / math.sqrt(2.0 ** (1.0 / order) - 1.0)
    return fs * math.sqrt(math.pi) * math.gamma(order - 0.5) / (2.0 * math.gamma(order))


def noise_rows(seconds: float) -> tuple[list[list[object]], list[list[object]]]:
    """The Allan rows and the noise-per-sample rows (see the module docstring)."""
    import allantools

    allan, per_sample = [], []
    for seed, (model, (_, _, bands, filter_rate)) in enumerate(NOISE_SETTINGS.items()):
        ge = READERS[model].family.gyro_errors
        n = ge.noise_density_rad_s_sqrt_hz
        chips: list[object] = []
        rate, odr, fc = still_stream(model, seconds, lowpass_hz=bands[0] if bands else None,
                                     seed=seed, chip_out=chips)
        taus = np.array([0.1, 1.0])
        adev = np.mean([allantools.oadev(rate[:, j], rate=odr, data_type="freq", taus=taus)[1]
                        for j in range(3)], axis=0)
        ratio = adev * np.sqrt(taus) / n
        allan.append([model, ge.noise_density_dps_sqrt_hz, float(ratio[0]), float(ratio[1]),
                      ge.noise_source])
        streams = [(rate, fc)] + [still_stream(model, seconds / 4, lowpass_hz=b, seed=seed,
                                               chip_out=chips)[::2] for b in bands[1:]]
        for (samples, cutoff), chip in zip(streams, chips, strict=True):
            per_sample.append(_per_sample_row(model, samples, cutoff, chip, n, filter_rate))
    return allan, per_sample


#: A datasheet delay column's entry where the chip table has none (for the ICM-20948 and the
#: ICM-42688-P none was found: what was searched is in their tables' comments,
#: ``drivers/imu/chips.py``): the emulated delay beside it is then its stand-in filter's own.
_NOT_PUBLISHED = "none found"


def _per_sample_row(model: str, samples: np.ndarray, cutoff: float | None, chip: object,
                    n: float, filter_rate: float) -> list[object]:
    """One row of the noise-per-sample table (see the module docstring)."""
    order = chip.filter_order() if cutoff else 0  # type: ignore[attr-defined]
    sigma = float(np.mean(np.std(samples, axis=0)))
    want = predicted_sigma(n, cutoff, filter_rate, max(order, 1))
    cont = n * math.sqrt(2 * analog_enbw_hz(cutoff, order)) if cutoff else float("nan")
    setting = chip.filter_setting()  # type: ignore[attr-defined]
    nbw = setting.noise_bandwidth_hz if setting is not None else None
    datasheet = n * math.sqrt(2 * nbw) if nbw else float("nan")
    delay = chip.output_delay_s()  # type: ignore[attr-defined]
    ds_delay = setting.delay_s if setting is not None else None
    return [model, cutoff or "none", order or "-", sigma / RAD_PER_DEG, want / RAD_PER_DEG,
            sigma / want, cont / RAD_PER_DEG, datasheet / RAD_PER_DEG,
            float("nan") if delay is None else delay * 1e3,
            _NOT_PUBLISHED if ds_delay is None else ds_delay * 1e3]


# model -> (odr_hz, three accelerometer filter settings as register writes after the reader
# started: (label, [(register, value) or (register, mask, value) read-modify-write, ...]))
ACCEL_SETTINGS: dict[str, tuple[float, tuple[tuple[str, list[tuple[int, ...]]], ...]]] = {
    # ACCEL_CONFIG_2 (0x1D) A_DLPFCFG 0 (the reset), 3, 6
    "mpu9250": (1000.0, (("A_DLPFCFG 0", [(0x1D, 0)]), ("A_DLPFCFG 3", [(0x1D, 3)]),
                         ("A_DLPFCFG 6", [(0x1D, 6)]))),
    # bank 2 (REG_BANK_SEL 0x7F = 0x20) ACCEL_CONFIG (0x14) bits 5:3 ACCEL_DLPFCFG 0, 3, 6
    "icm20948": (1125.0, tuple((f"ACCEL_DLPFCFG {c}", [(0x7F, 0x20), (0x14, 0x38, c << 3),
                                                       (0x7F, 0x00)]) for c in (0, 3, 6))),
    # GYRO_ACCEL_CONFIG0 (0x52) bits 7:4 ACCEL_UI_FILT_BW 1 (the reset), 3, 7
    "icm42688p": (1000.0, tuple((f"ACCEL_UI_FILT_BW {c}", [(0x52, 0xF0, c << 4)])
                                for c in (1, 3, 7))),
    # CTRL1_XL (0x10) bit 1 LPF2_XL_EN off (LPF1, ODR/2: the per-sample mean); on with CTRL8_XL
    # (0x17) HPCF_XL 000 (ODR/4) and 100 (ODR/100), AN5192 Table 10
    "lsm6dsox": (208.0, (("LPF2 off", []),
                         ("HPCF_XL 000", [(0x10, 0x02, 0x02), (0x17, 0x00)]),
                         ("HPCF_XL 100", [(0x10, 0x02, 0x02), (0x17, 0x80)]))),
    # CTRL_REG6_XL (0x20) BW_SCAL_ODR 0 (105 Hz at 238 Hz) or 1 with BW_XL 11 (50 Hz);
    # CTRL_REG7_XL (0x21) HR with DCF 10 (ODR/9)
    "lsm9ds1": (238.0, (("BW_SCAL_ODR 0", []), ("BW_XL 11", [(0x20, 0x07, 0x07)]),
                        ("HR, DCF 10", [(0x21, 0xC0)]))),
}


def accel_still_stream(model: str, seconds: float, odr: float, write=(), seed: int = 3
                       ) -> tuple[np.ndarray, float, object]:
    """``seconds`` of a chip at rest through its reader at ``odr``, its accelerometer with the
    chip table's noise density and no other error, the register writes ``write`` made after
    the reader started ((register, value), or (register, mask, value) to change the masked
    bits): the accelerometer samples (N, 3) in m/s² past the filter's start, the density in
    m/s²/√Hz and the emulated chip."""
    from gyrocal.drivers.emulated.accel import AccelTruth

    density_g = READERS[model].family.accel_errors.noise_g_sqrt_hz
    clock = VirtualClock()
    truth = SensorTruth(accelerometer=AccelTruth(noise_density_g_sqrt_hz=density_g))
    bus, addr = make_emulated_imu(model, clock, truth=truth, seed=seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reader = open_imu(model, bus, addr, clock=clock, range_dps=500, odr_hz=odr)
    reader.start()
    for w in write:
        register, value = w[0], w[-1]
        if len(w) == 3:
            value = (bus.read_byte_data(addr, register) & ~w[1] & 0xFF) | value
        bus.write_byte_data(addr, register, value)
    chunks = []
    while clock.monotonic() < seconds:
        clock.sleep(0.02)
        chunks.append(reader.read().accel)
    return np.vstack(chunks)[int(0.3 * odr):], density_g * 9.80665, bus.device(addr)


def accel_rows(seconds: float) -> list[list[object]]:
    """The accelerometer's noise per sample at three filter settings per chip against the
    design (:func:`predicted_sigma` at the filter's rate) and, where the datasheet gives one,
    its noise bandwidth."""
    rows: list[list[object]] = []
    for model, (odr, settings) in ACCEL_SETTINGS.items():
        for label, write in settings:
            a, n, chip = accel_still_stream(model, seconds, odr, write)
            setting = chip.accel_filter_setting()  # type: ignore[attr-defined]
            key = chip._accel_filter_key(odr)  # type: ignore[attr-defined]
            fc, order, rate = key if key is not None else (None, 0, odr)
            sigma = float(np.mean(np.std(a, axis=0)))
            want = predicted_sigma(n, fc, rate, max(order, 1))
            nbw = setting.noise_bandwidth_hz if setting is not None else None
            rows.append([model, label, setting.bandwidth_hz if setting else "none",
                         order or "-", rate, sigma * 1e3 / 9.80665, want * 1e3 / 9.80665,
                         sigma / want,
                         n * math.sqrt(2 * nbw) * 1e3 / 9.80665 if nbw else float("nan"),
                         setting.delay_s * 1e3 if setting and setting.delay_s else _NOT_PUBLISHED,
                         n * math.sqrt(odr) * 1e3 / 9.80665])
    return rows


def sim_rate_rows(seconds: float) -> list[list[object]]:
    """Each chip at rest through its reader at ``--sim``'s rate (200 Hz asked, the nearest the
    reader offers) with the reader's default filter: the bandwidth the reader states, the one
    the emulated chip applies, the rate its filter runs at, and the gyro noise per sample
    against the design at that rate (:func:`predicted_sigma`) and against the analog
    prototype's ``N √(2 ENBW)``."""
    from gyrocal.drivers.imu import nearest_offered_rate

    rows: list[list[object]] = []
    for seed, model in enumerate(sorted(READERS)):
        odr = nearest_offered_rate(model, 200.0)
        clock = VirtualClock()
        bus, addr = make_emulated_imu(model, clock, seed=seed)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            reader = open_imu(model, bus, addr, clock=clock, range_dps=500, odr_hz=odr)
        reader.start()
        chunks = []
        while clock.monotonic() < seconds:
            clock.sleep(0.02)
            chunks.append(reader.read().rate)
        rate = np.vstack(chunks)[int(0.5 * odr):]
        chip = bus.device(addr)
        fc, order = chip.cutoff_hz(), chip.filter_order()
        filter_rate = chip._filter_rate_hz()
        n = READERS[model].family.gyro_errors.noise_density_rad_s_sqrt_hz
        sigma = float(np.mean(np.std(rate, axis=0)))
        want = predicted_sigma(n, fc, filter_rate, order)
        analog = n * math.sqrt(2 * analog_enbw_hz(fc, order)) if fc else float("nan")
        rows.append([model, odr, reader.info.lowpass_hz, fc or "none", order, filter_rate,
                     sigma / RAD_PER_DEG, want / RAD_PER_DEG, sigma / want,
                     analog / RAD_PER_DEG])
    return rows


def main(argv: list[str]) -> None:
    """Print the table (see the module docstring)."""
    quick = "--quick" in argv
    seeds, seconds = ((0,), 5.0) if quick else ((0, 1, 2), 10.0)
    rows = [_run(model, seed, seconds) for model in CHIPS for seed in seeds]
    print_table(["chip", "seed", "gaps", "lost reported - missing", "median us", "p99 us",
                 "max us"], rows,
                title=f"FIFO stress ({seconds:g} s, ~16-sample FIFO, drains every 3-20 ms), "
                      "emulated bus")
    noise_s = 20.0 if quick else 120.0
    allan, per_sample = noise_rows(noise_s)
    print_table(["chip", "N °/s/√Hz", "σ_A(0.1 s)·√τ / N", "σ_A(1 s)·√τ / N", "source"], allan,
                title=f"Allan deviation at rest against the datasheet density ({noise_s:g} s, "
                      "allantools oadev, mean of the axes; 1 is right)")
    print_table(["chip", "filter Hz", "order", "σ/sample °/s", "predicted °/s", "ratio",
                 "N√(2 ENBW) °/s", "N√(2 NBW) datasheet °/s", "emulated delay ms",
                 "datasheet delay ms"], per_sample,
                title="Noise per sample against the filter bandwidth (white noise ahead of the "
                      "filter)")
    print_table(["chip", "odr Hz", "reader's filter Hz", "emulated filter Hz", "order",
                 "filter rate Hz", "σ/sample °/s", "predicted °/s", "ratio",
                 "N√(2 ENBW) °/s"], sim_rate_rows(noise_s / 4),
                title="At --sim's rate (200 Hz asked), the reader's default filter: stated and "
                      "emulated bandwidth, noise per sample")
    accel = accel_rows(5.0 if quick else 20.0)
    print_table(["chip", "setting", "filter Hz", "order", "filter rate Hz", "σ/sample mg",
                 "predicted mg", "ratio", "N√(2 NBW) datasheet mg", "datasheet delay ms",
                 "unfiltered N√odr mg"], accel,
                title="Accelerometer noise per sample against its filter (white noise ahead of "
                      "the filter, the chip table's density)")
