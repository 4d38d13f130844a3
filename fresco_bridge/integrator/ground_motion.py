"""Ground-motion records for the built-in pseudo-dynamic integrator.

A :class:`GroundMotion` stores the acceleration in units of g (the unit of PEER records) and
exposes it in m/s^2 and in mm/s^2 (the integrator's default unit system is mm, kN, s).
Records come from PEER NGA ``.AT2`` files, from plain-text files (one time/accel pair per line,
or values only), or from :func:`kanai_tajimi`, a seeded synthetic record used when no real record
is at hand (the source paper's Simi Valley record is not available to the project).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

__all__ = [
    "G_MM_S2",
    "G_M_S2",
    "GroundMotion",
    "GroundMotionFormatError",
    "JenningsEnvelope",
    "kanai_tajimi",
    "read_ground_motion",
    "read_peer_at2",
]

G_M_S2 = 9.80665
"""Standard gravity in m/s^2 (the g of PEER records)."""
G_MM_S2 = G_M_S2 * 1000.0

_FLOAT_RE = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[EeDd][-+]?\d+)?")
_NPTS_DT_RE = re.compile(
    r"NPTS\s*=\s*(?P<npts>\d+)\s*[,;]?\s*DT\s*=\s*(?P<dt>[-+]?(?:\d+\.?\d*|\.\d+)(?:[Ee][-+]?\d+)?)",
    re.IGNORECASE,
)
_UNIT_SCALE_TO_G = {
    "G": 1.0,
    "CM/S/S": 1.0 / (G_M_S2 * 100.0),
    "CM/SEC/SEC": 1.0 / (G_M_S2 * 100.0),
    "CM/S2": 1.0 / (G_M_S2 * 100.0),
    "CM/S^2": 1.0 / (G_M_S2 * 100.0),
    "M/S/S": 1.0 / G_M_S2,
    "M/S2": 1.0 / G_M_S2,
    "M/S^2": 1.0 / G_M_S2,
}


class GroundMotionFormatError(ValueError):
    """A record file that cannot be read; the message names the file, the line and the reason."""

    def __init__(self, path: Path | str, line: int | None, reason: str) -> None:
        where = f"{path}:{line}" if line is not None else f"{path}"
        super().__init__(f"{where}: {reason}")
        self.path = str(path)
        self.line = line
        self.reason = reason


@dataclass(frozen=True, eq=False)
class GroundMotion:
    """A uniformly sampled ground acceleration: ``accel[n]`` (in g) at time ``n * dt`` (s)."""

    dt: float
    accel: npt.NDArray[np.float64]
    name: str
    source: str

    def __post_init__(self) -> None:
        if not (math.isfinite(self.dt) and self.dt > 0.0):
            raise ValueError(
                f"GroundMotion {self.name!r}: dt must be finite and > 0, got {self.dt}"
            )
        accel = np.array(self.accel, dtype=np.float64)
        if accel.ndim != 1 or accel.size < 2:
            raise ValueError(
                f"GroundMotion {self.name!r}: accel must be 1-D with at least 2 samples, "
                f"got shape {accel.shape}"
            )
        bad = np.flatnonzero(~np.isfinite(accel))
        if bad.size:
            raise ValueError(
                f"GroundMotion {self.name!r}: accel has a non-finite value at index {bad[0]}"
            )
        accel.flags.writeable = False
        object.__setattr__(self, "accel", accel)

    @property
    def npts(self) -> int:
        return int(self.accel.size)

    @property
    def duration(self) -> float:
        """Time of the last sample (s)."""
        return (self.npts - 1) * self.dt

    @property
    def time(self) -> npt.NDArray[np.float64]:
        return np.arange(self.npts, dtype=np.float64) * self.dt

    @property
    def pga(self) -> float:
        """Peak ground acceleration in g (the unit of ``accel``)."""
        return float(np.max(np.abs(self.accel)))

    @property
    def pga_m_s2(self) -> float:
        return self.pga * G_M_S2

    @property
    def accel_m_s2(self) -> npt.NDArray[np.float64]:
        return self.accel * G_M_S2

    @property
    def accel_mm_s2(self) -> npt.NDArray[np.float64]:
        """Acceleration in mm/s^2, the unit the integrator uses with masses in kN*s^2/mm."""
        return self.accel * G_MM_S2

    def scaled_to_pga(self, pga_m_s2: float) -> GroundMotion:
        """The same record scaled so that its peak absolute acceleration is ``pga_m_s2``."""
        if not (math.isfinite(pga_m_s2) and pga_m_s2 > 0.0):
            raise ValueError(f"target PGA must be finite and > 0 m/s^2, got {pga_m_s2}")
        peak = self.pga
        if peak == 0.0:
            raise ValueError(f"GroundMotion {self.name!r} is all zeros and cannot be scaled")
        factor = pga_m_s2 / (peak * G_M_S2)
        return GroundMotion(
            dt=self.dt,
            accel=self.accel * factor,
            name=self.name,
            source=f"{self.source}; scaled x{factor:.6g} to PGA {pga_m_s2:g} m/s^2",
        )

    def resampled(self, dt: float) -> GroundMotion:
        """The record at a new time step by linear interpolation, over the same duration."""
        if not (math.isfinite(dt) and dt > 0.0):
            raise ValueError(f"resampling dt must be finite and > 0, got {dt}")
        n_new = math.floor(self.duration / dt + 1e-9) + 1
        if n_new < 2:
            raise ValueError(
                f"resampling dt={dt} s is longer than the record duration {self.duration} s"
            )
        t_new = np.arange(n_new, dtype=np.float64) * dt
        accel = np.interp(t_new, self.time, self.accel)
        return GroundMotion(
            dt=dt,
            accel=accel,
            name=self.name,
            source=f"{self.source}; resampled dt {self.dt:g} -> {dt:g} s (linear)",
        )


# ---------------------------------------------------------------------------------------------
# file readers


def _parse_numbers(path: Path, line_no: int, text: str) -> list[float]:
    """All numbers of one data line; anything else on it is an error (Fortran D exponents ok)."""
    values: list[float] = []
    leftover = _FLOAT_RE.sub(" ", text).strip()
    if leftover:
        raise GroundMotionFormatError(path, line_no, f"non-numeric value {leftover.split()[0]!r}")
    for token in _FLOAT_RE.findall(text):
        values.append(float(token.replace("D", "E").replace("d", "e")))
    return values


def _at2_npts_dt(path: Path, header: str) -> tuple[int, float]:
    match = _NPTS_DT_RE.search(header)
    if match:
        npts, dt = int(match["npts"]), float(match["dt"])
    elif "NPTS" in header.upper() and "DT" in header.upper():
        # Old NGA layout: "  5590   .0050   NPTS, DT" (numbers first, then the labels).
        numbers = _FLOAT_RE.findall(header.upper().split("NPTS")[0])
        if len(numbers) < 2:
            raise GroundMotionFormatError(
                path, 4, f"cannot find NPTS and DT values in header {header.strip()!r}"
            )
        try:
            npts_f = float(numbers[0])
        except ValueError as exc:  # pragma: no cover - the regex only yields numbers
            raise GroundMotionFormatError(path, 4, f"bad NPTS {numbers[0]!r}") from exc
        if npts_f != int(npts_f):
            raise GroundMotionFormatError(path, 4, f"NPTS is not an integer: {numbers[0]!r}")
        npts, dt = int(npts_f), float(numbers[1])
    else:
        raise GroundMotionFormatError(
            path, 4, f"header line 4 must give NPTS and DT, got {header.strip()!r}"
        )
    if npts < 2:
        raise GroundMotionFormatError(path, 4, f"NPTS must be >= 2, got {npts}")
    if not (math.isfinite(dt) and dt > 0.0):
        raise GroundMotionFormatError(path, 4, f"DT must be > 0, got {dt}")
    return npts, dt


def _at2_unit_scale(path: Path, line3: str) -> float:
    upper = line3.upper()
    for kind in ("VELOCITY", "DISPLACEMENT"):
        if kind in upper:
            raise GroundMotionFormatError(
                path, 3, f"this is a {kind.lower()} record, an acceleration record is needed"
            )
    match = re.search(r"UNITS\s+OF\s+(\S+)", upper)
    if match is None:
        return 1.0  # PEER acceleration records are in g when they do not say otherwise
    unit = match.group(1).rstrip(".,")
    if unit not in _UNIT_SCALE_TO_G:
        raise GroundMotionFormatError(path, 3, f"unknown acceleration unit {unit!r}")
    return _UNIT_SCALE_TO_G[unit]


def read_peer_at2(path: str | Path) -> GroundMotion:
    """Read a PEER NGA ``.AT2`` acceleration record (4 header lines, then the values in g).

    Header line 4 gives NPTS and DT as ``NPTS= 5590, DT= .0050 SEC`` or, in old files, as
    ``5590  .0050  NPTS, DT``. Files padded with trailing zeros past NPTS on the last line
    (RSN960 holds 2000 values for NPTS=1999) are accepted; any other count mismatch is an error.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="ascii", errors="strict")
    except UnicodeDecodeError as exc:
        raise GroundMotionFormatError(path, None, f"not an ASCII text file ({exc.reason})") from exc
    lines = text.splitlines()
    if len(lines) < 5:
        raise GroundMotionFormatError(
            path, len(lines) or None, f"an AT2 file needs 4 header lines and data, got {len(lines)}"
        )
    npts, dt = _at2_npts_dt(path, lines[3])
    scale = _at2_unit_scale(path, lines[2])
    values: list[float] = []
    last_line_no = 4
    for index, line in enumerate(lines[4:], start=5):
        if not line.strip():
            continue
        if len(values) >= npts:
            extra = _parse_numbers(path, index, line)
            if any(v != 0.0 for v in extra) or index != len(lines):
                raise GroundMotionFormatError(
                    path, index, f"more values than NPTS={npts} from the header"
                )
            continue
        row = _parse_numbers(path, index, line)
        values.extend(row)
        last_line_no = index
    if len(values) < npts:
        raise GroundMotionFormatError(
            path, last_line_no, f"header says NPTS={npts} but the file holds {len(values)} values"
        )
    padding = values[npts:]
    if any(v != 0.0 for v in padding):
        raise GroundMotionFormatError(
            path,
            last_line_no,
            f"header says NPTS={npts} but the file holds {len(values)} values "
            "(extra values that are not zero padding)",
        )
    accel = np.asarray(values[:npts], dtype=np.float64) * scale
    return GroundMotion(
        dt=dt, accel=accel, name=path.stem, source=f"PEER AT2 {path.name}: {lines[1].strip()}"
    )


def _read_text_record(path: Path, lines: list[str], dt: float | None, scale: float) -> GroundMotion:
    rows: list[tuple[int, list[float]]] = []
    for index, line in enumerate(lines, start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        rows.append((index, _parse_numbers(path, index, line)))
    if not rows:
        raise GroundMotionFormatError(path, None, "the file holds no values")
    widths = {len(r) for _, r in rows}
    is_time_accel = widths == {2} and len(rows) >= 2
    if is_time_accel:
        times = np.array([r[0] for _, r in rows])
        steps = np.diff(times)
        step = float(np.median(steps))
        if step <= 0.0 or np.max(np.abs(steps - step)) > 1e-6 * max(1.0, float(times[-1])):
            is_time_accel = False  # not a time column: treat as a flat list of values
    if is_time_accel:
        record_dt = float((times[-1] - times[0]) / (len(times) - 1))
        if dt is not None and not math.isclose(dt, record_dt, rel_tol=1e-6):
            raise GroundMotionFormatError(
                path, None, f"dt={dt} given but the time column has a step of {record_dt:.9g} s"
            )
        accel = np.array([r[1] for _, r in rows]) * scale
        return GroundMotion(
            dt=round(record_dt, 12),
            accel=accel,
            name=path.stem,
            source=f"text {path.name} (time, accel) t0={times[0]:g} s",
        )
    if dt is None:
        raise GroundMotionFormatError(
            path, rows[0][0], "the file has no time column and no header: pass dt="
        )
    values = [v for _, row in rows for v in row]
    return GroundMotion(
        dt=dt, accel=np.asarray(values) * scale, name=path.stem, source=f"text {path.name}"
    )


def read_ground_motion(path: str | Path, dt: float | None = None, unit: str = "g") -> GroundMotion:
    """Read a record, choosing the format from the content.

    A file whose header says ``NPTS`` on line 4 (or starts with ``PEER``) is read as AT2. Other
    files are plain numbers: two columns with a uniform first column are (time, accel); any
    other layout is a flat list of values, read in order, and then ``dt`` is required.
    ``unit`` (``g``, ``m/s2``, ``cm/s2``) applies to plain-text files only.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="ascii", errors="strict")
    except UnicodeDecodeError as exc:
        raise GroundMotionFormatError(path, None, f"not an ASCII text file ({exc.reason})") from exc
    lines = text.splitlines()
    head = [line.upper() for line in lines[:4]]
    if (head and head[0].startswith("PEER")) or (len(head) == 4 and "NPTS" in head[3]):
        return read_peer_at2(path)
    unit_key = unit.upper().replace("S^2", "S2")
    if unit_key not in _UNIT_SCALE_TO_G:
        raise ValueError(f"unknown acceleration unit {unit!r}; use g, m/s2 or cm/s2")
    return _read_text_record(path, lines, dt, _UNIT_SCALE_TO_G[unit_key])


# ---------------------------------------------------------------------------------------------
# synthetic record


@dataclass(frozen=True)
class JenningsEnvelope:
    """Jennings-type amplitude envelope: quadratic rise, flat strong part, exponential decay.

    e(t) = (t/t_rise)^2 before ``t_rise``, 1 until ``t_strong_end``, then
    exp(-decay_rate * (t - t_strong_end)).
    """

    t_rise: float
    t_strong_end: float
    decay_rate: float

    def __post_init__(self) -> None:
        if not (0.0 <= self.t_rise <= self.t_strong_end) or self.decay_rate < 0.0:
            raise ValueError(
                "JenningsEnvelope needs 0 <= t_rise <= t_strong_end and decay_rate >= 0, got "
                f"t_rise={self.t_rise}, t_strong_end={self.t_strong_end}, "
                f"decay_rate={self.decay_rate}"
            )

    @classmethod
    def for_duration(cls, duration: float, end_level: float = 0.05) -> JenningsEnvelope:
        """Rise over the first 10 %, strong part to 50 %, decay to ``end_level`` at the end."""
        t_rise, t_strong_end = 0.1 * duration, 0.5 * duration
        return cls(t_rise, t_strong_end, -math.log(end_level) / (duration - t_strong_end))

    def __call__(self, t: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        rise = np.ones_like(t) if self.t_rise == 0.0 else np.clip(t / self.t_rise, 0.0, 1.0) ** 2
        decay = np.exp(-self.decay_rate * np.clip(t - self.t_strong_end, 0.0, None))
        return np.asarray(rise * decay, dtype=np.float64)


def _kanai_tajimi_filter(
    noise: npt.NDArray[np.float64], dt: float, omega_g: float, zeta_g: float
) -> npt.NDArray[np.float64]:
    """Filter white noise through H(w) = (wg^2 + 2i zg wg w) / (wg^2 - w^2 + 2i zg wg w).

    Done in the frequency domain, zero-padded so the circular convolution does not wrap.
    """
    n = noise.size
    n_fft = 1 << (2 * n - 1).bit_length()
    omega = 2.0 * np.pi * np.fft.rfftfreq(n_fft, d=dt)
    numerator = omega_g**2 + 2j * zeta_g * omega_g * omega
    transfer = numerator / (omega_g**2 - omega**2 + 2j * zeta_g * omega_g * omega)
    spectrum = np.fft.rfft(noise, n=n_fft) * transfer
    return np.asarray(np.fft.irfft(spectrum, n=n_fft)[:n], dtype=np.float64)


def _baseline_correct(
    accel: npt.NDArray[np.float64], weight: npt.NDArray[np.float64], dt: float
) -> npt.NDArray[np.float64]:
    """Subtract weight(t) * (c0 + c1 t) so the final velocity and displacement are zero.

    Velocity and displacement use the trapezoidal rule, as the integrator sees a piecewise
    linear ground acceleration; the weight (the envelope) keeps the correction zero at t = 0.
    """
    t = np.arange(accel.size) * dt

    def final_vel_disp(a: npt.NDArray[np.float64]) -> tuple[float, float]:
        vel = np.concatenate(([0.0], np.cumsum(0.5 * (a[1:] + a[:-1]) * dt)))
        disp = float(np.sum(0.5 * (vel[1:] + vel[:-1]) * dt))
        return float(vel[-1]), disp

    basis = [weight, weight * t / t[-1]]
    columns = [final_vel_disp(b) for b in basis]
    matrix = np.array(columns).T
    target = np.array(final_vel_disp(accel))
    coeffs = np.linalg.solve(matrix, target)
    return np.asarray(accel - coeffs[0] * basis[0] - coeffs[1] * basis[1], dtype=np.float64)


def kanai_tajimi(
    pga_m_s2: float,
    duration: float = 20.0,
    dt: float = 0.01,
    seed: int = 0,
    omega_g: float = 15.6,
    zeta_g: float = 0.6,
    envelope: JenningsEnvelope | None = None,
) -> GroundMotion:
    """A seeded synthetic record: Kanai-Tajimi filtered white noise under a Jennings envelope.

    The stationary part has the Kanai-Tajimi spectral shape (``omega_g`` rad/s, ``zeta_g``;
    the defaults are the classic firm-soil values). The enveloped record is baseline-corrected
    (zero final velocity and displacement) and scaled so its PGA is exactly ``pga_m_s2``.
    The same arguments always give the same record (numpy PCG64 generator).
    """
    for name, value in (("pga_m_s2", pga_m_s2), ("duration", duration), ("dt", dt)):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"kanai_tajimi: {name} must be finite and > 0, got {value}")
    if not (omega_g > 0.0 and zeta_g > 0.0):
        raise ValueError(f"kanai_tajimi: omega_g and zeta_g must be > 0, got {omega_g}, {zeta_g}")
    npts = round(duration / dt) + 1
    if npts < 16:
        raise ValueError(f"kanai_tajimi: duration/dt gives only {npts} samples, need >= 16")
    env = envelope if envelope is not None else JenningsEnvelope.for_duration(duration)
    rng = np.random.default_rng(seed)
    noise = rng.standard_normal(npts)
    stationary = _kanai_tajimi_filter(noise, dt, omega_g, zeta_g)
    weight = env(np.arange(npts, dtype=np.float64) * dt)
    accel = _baseline_correct(stationary * weight, weight, dt)
    accel *= (pga_m_s2 / G_M_S2) / np.max(np.abs(accel))
    return GroundMotion(
        dt=dt,
        accel=accel,
        name=f"kanai_tajimi_seed{seed}",
        source=(
            f"synthetic Kanai-Tajimi (omega_g={omega_g:g} rad/s, zeta_g={zeta_g:g}, seed={seed}, "
            f"{env}), baseline-corrected, PGA {pga_m_s2:g} m/s^2"
        ),
    )
