"""Ground-motion readers (all shared records) and the seeded Kanai-Tajimi generator."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from fresco_bridge.integrator.ground_motion import (
    G_M_S2,
    GroundMotion,
    GroundMotionFormatError,
    JenningsEnvelope,
    kanai_tajimi,
    read_ground_motion,
    read_peer_at2,
)
from tests.support.paths import GROUND_MOTIONS

RECORDS = GROUND_MOTIONS
needs_shared = pytest.mark.skipif(
    not RECORDS.is_dir(), reason=f"shared ground motions not found at {RECORDS}"
)
AT2_FILES = sorted(RECORDS.glob("*.AT2")) if RECORDS.is_dir() else []


def _readme_table() -> dict[str, tuple[int, float, float]]:
    """file -> (npts, dt, PGA in g) as documented in the shared README (independent source)."""
    table: dict[str, tuple[int, float, float]] = {}
    for line in (RECORDS / "README.md").read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) < 6 or not re.search(r"\.(AT2|txt)$", cells[0]):
            continue
        npts = int(re.match(r"\d+", cells[2]).group())  # type: ignore[union-attr]
        dt = float(re.match(r"[\d.]+", cells[3]).group())  # type: ignore[union-attr]
        pga = float(re.match(r"[\d.]+", cells[4]).group())  # type: ignore[union-attr]
        table[cells[0]] = (npts, dt, pga)
    return table


def _header_npts_dt(path: Path) -> tuple[int, float]:
    line4 = path.read_text().splitlines()[3]
    npts = int(line4.split("NPTS=")[1].split(",")[0])
    dt = float(line4.split("DT=")[1].split()[0].rstrip(","))
    return npts, dt


@needs_shared
@pytest.mark.parametrize("path", AT2_FILES, ids=lambda p: p.name)
def test_every_shared_at2_parses_with_header_counts_and_readme_pga(path: Path) -> None:
    gm = read_peer_at2(path)
    npts, dt = _header_npts_dt(path)
    assert gm.npts == npts
    assert gm.dt == dt
    readme_npts, readme_dt, readme_pga = _readme_table()[path.name]
    assert (gm.npts, gm.dt) == (readme_npts, readme_dt)
    assert gm.pga == pytest.approx(readme_pga, abs=6e-5)
    assert 0.01 < gm.pga < 2.0  # a strong-motion record in g, not cm/s^2
    assert gm.name == path.stem
    assert path.name in gm.source and ("Northridge" in gm.source or "Imperial" in gm.source)
    # the first and last values as printed in the file
    data_tokens = " ".join(path.read_text().splitlines()[4:]).split()
    assert gm.accel[0] == float(data_tokens[0])
    assert gm.accel[-1] == float(data_tokens[npts - 1])


@needs_shared
def test_shared_at2_set_is_not_empty() -> None:
    assert len(AT2_FILES) >= 8


@needs_shared
def test_text_records_from_shared_data() -> None:
    table = _readme_table()
    elc = read_ground_motion(RECORDS / "ELC270_OpenFresco.txt", dt=0.01)
    assert elc.npts == table["ELC270_OpenFresco.txt"][0] == 4000
    assert np.all(elc.accel[:5] == 0.0)
    assert elc.pga == pytest.approx(table["ELC270_OpenFresco.txt"][2], abs=6e-5)
    with pytest.raises(GroundMotionFormatError, match=r"no time column.*dt="):
        read_ground_motion(RECORDS / "ELC270_OpenFresco.txt")

    two_col = read_ground_motion(RECORDS / "elCentro_OpenSeesPyExamples.txt")
    assert (two_col.npts, two_col.dt) == table["elCentro_OpenSeesPyExamples.txt"][:2]
    assert two_col.pga == pytest.approx(table["elCentro_OpenSeesPyExamples.txt"][2], abs=6e-5)
    assert two_col.accel[1] == pytest.approx(0.00364)
    with pytest.raises(GroundMotionFormatError, match=r"time column has a step of 0\.02"):
        read_ground_motion(RECORDS / "elCentro_OpenSeesPyExamples.txt", dt=0.01)

    at2 = read_ground_motion(RECORDS / "Rinaldi228.AT2")
    assert at2.npts == 1991  # dispatched to the AT2 reader, not read as plain numbers


@needs_shared
def test_rsn1084_resampled_to_0_01_keeps_every_other_sample() -> None:
    gm = read_peer_at2(RECORDS / "RSN1084_NORTHR_SCS052.AT2")
    coarse = gm.resampled(0.01)
    assert coarse.dt == 0.01
    assert coarse.npts == (gm.npts - 1) // 2 + 1
    np.testing.assert_allclose(coarse.accel, gm.accel[::2][: coarse.npts], atol=1e-15)


def _write_at2(tmp_path: Path, line4: str, data: str, line3: str = "") -> Path:
    path = tmp_path / "rec.AT2"
    head = [
        "PEER NGA STRONG MOTION DATABASE RECORD",
        "Test event, station, 000",
        line3 or "ACCELERATION TIME SERIES IN UNITS OF G",
        line4,
    ]
    path.write_text("\n".join(head) + "\n" + data)
    return path


def test_at2_header_spellings(tmp_path: Path) -> None:
    data = "  .1E-01  -.2E-01   .3E-01\n  -.4E-01   .5E-01\n"
    for line4 in (
        "NPTS=   5, DT=   .0050 SEC,   4 POLE @ 40.0 HZ",
        "NPTS=  5, DT= .0050 SEC",
        "   5    .0050    NPTS, DT",
        "5  0.0050  NPTS, DT, SEC",
    ):
        gm = read_peer_at2(_write_at2(tmp_path, line4, data))
        assert gm.npts == 5 and gm.dt == 0.005, line4
        np.testing.assert_array_equal(gm.accel, [0.01, -0.02, 0.03, -0.04, 0.05])


def test_at2_other_units_are_converted_to_g(tmp_path: Path) -> None:
    line3 = "ACCELERATION TIME SERIES IN UNITS OF CM/S/S"
    gm = read_peer_at2(_write_at2(tmp_path, "NPTS= 2, DT= .01", "980.665 -490.3325\n", line3))
    np.testing.assert_allclose(gm.accel, [1.0, -0.5])


@pytest.mark.parametrize(
    ("line4", "data", "line3", "pattern"),
    [
        ("DT= .01 SEC", "1 2\n", "", r"rec\.AT2:4: header line 4 must give NPTS and DT"),
        ("NPTS= 4, DT= .01", ".1 .2 .3\n", "", r"NPTS=4 but the file holds 3 values"),
        ("NPTS= 2, DT= .01", ".1 .2\n.3 .4\n", "", r"rec\.AT2:6: more values than NPTS=2"),
        ("NPTS= 2, DT= .01", ".1 .2 .3\n", "", r"extra values that are not zero padding"),
        ("NPTS= 3, DT= .01", ".1 abc .3\n", "", r"rec\.AT2:5: non-numeric value 'abc'"),
        ("NPTS= 3, DT= 0", ".1 .2 .3\n", "", r":4: DT must be > 0"),
        ("NPTS= 2, DT= .01", ".1 .2\n", "VELOCITY TIME SERIES IN UNITS OF CM/S", r"velocity"),
        ("NPTS= 2, DT= .01", ".1 .2\n", "ACCELERATION IN UNITS OF FT/S2", r"unknown .*FT/S2"),
    ],
)
def test_at2_errors_name_file_line_and_reason(
    tmp_path: Path, line4: str, data: str, line3: str, pattern: str
) -> None:
    with pytest.raises(GroundMotionFormatError, match=pattern):
        read_peer_at2(_write_at2(tmp_path, line4, data, line3))


def test_at2_trailing_zero_padding_is_dropped(tmp_path: Path) -> None:
    gm = read_peer_at2(_write_at2(tmp_path, "NPTS= 3, DT= .01", ".1 .2\n.3 .0\n"))
    np.testing.assert_array_equal(gm.accel, [0.1, 0.2, 0.3])


def test_too_short_file(tmp_path: Path) -> None:
    path = tmp_path / "short.AT2"
    path.write_text("PEER NGA\nx\n")
    with pytest.raises(GroundMotionFormatError, match="4 header lines"):
        read_peer_at2(path)


def test_scaling_and_resampling() -> None:
    gm = GroundMotion(dt=0.02, accel=np.array([0.0, 0.1, -0.3, 0.2]), name="t", source="test")
    scaled = gm.scaled_to_pga(3.0)
    assert scaled.pga_m_s2 == pytest.approx(3.0, rel=1e-14)
    assert scaled.accel[2] == pytest.approx(-3.0 / G_M_S2)
    np.testing.assert_allclose(scaled.accel_mm_s2, scaled.accel_m_s2 * 1000.0)
    fine = gm.resampled(0.01)
    np.testing.assert_allclose(fine.accel, [0.0, 0.05, 0.1, -0.1, -0.3, -0.05, 0.2], atol=1e-15)
    with pytest.raises(ValueError, match="all zeros"):
        GroundMotion(dt=0.01, accel=np.zeros(4), name="z", source="").scaled_to_pga(1.0)
    with pytest.raises(ValueError, match="non-finite value at index 1"):
        GroundMotion(dt=0.01, accel=np.array([0.0, np.nan]), name="n", source="")
    with pytest.raises(ValueError, match="read-only"):
        gm.accel[0] = 1.0


# ---------------------------------------------------------------------------------------------
# Kanai-Tajimi


def test_kanai_tajimi_is_deterministic_and_exactly_scaled() -> None:
    a = kanai_tajimi(3.0, seed=7)
    b = kanai_tajimi(3.0, seed=7)
    c = kanai_tajimi(3.0, seed=8)
    np.testing.assert_array_equal(a.accel, b.accel)
    assert not np.allclose(a.accel, c.accel)
    assert a.npts == 2001 and a.dt == 0.01
    assert a.pga_m_s2 == pytest.approx(3.0, rel=1e-14)
    assert abs(a.accel[0]) < 1e-12  # the envelope starts at zero


def test_kanai_tajimi_is_baseline_corrected() -> None:
    gm = kanai_tajimi(3.0, seed=3)
    a = gm.accel_m_s2
    vel = np.concatenate(([0.0], np.cumsum(0.5 * (a[1:] + a[:-1]) * gm.dt)))
    disp = np.concatenate(([0.0], np.cumsum(0.5 * (vel[1:] + vel[:-1]) * gm.dt)))
    assert abs(vel[-1]) < 1e-9 * np.max(np.abs(vel))
    assert abs(disp[-1]) < 1e-9 * np.max(np.abs(disp))


def _kt_psd(omega: np.ndarray, omega_g: float, zeta_g: float) -> np.ndarray:
    num = omega_g**4 + 4 * zeta_g**2 * omega_g**2 * omega**2
    return num / ((omega_g**2 - omega**2) ** 2 + 4 * zeta_g**2 * omega_g**2 * omega**2)


@pytest.mark.parametrize(("omega_g", "zeta_g"), [(15.6, 0.6), (25.0, 0.25)])
def test_kanai_tajimi_spectral_shape(omega_g: float, zeta_g: float) -> None:
    duration, dt = 40.96, 0.01
    flat = JenningsEnvelope(0.0, duration, 0.0)  # stationary part only
    periodograms = []
    for seed in range(12):
        gm = kanai_tajimi(1.0, duration=duration, dt=dt, seed=seed, omega_g=omega_g,
                          zeta_g=zeta_g, envelope=flat)  # fmt: skip
        spectrum = np.abs(np.fft.rfft(gm.accel)) ** 2
        periodograms.append(spectrum / np.sum(spectrum))
    omega = 2 * np.pi * np.fft.rfftfreq(gm.npts, d=dt)
    mean = np.mean(periodograms, axis=0)
    kernel = np.ones(41) / 41  # smooth over +-0.6 rad/s
    smooth = np.convolve(mean, kernel, mode="same")
    band = (omega > 2.0) & (omega < 100.0)
    analytic = _kt_psd(omega, omega_g, zeta_g)
    peak_est = omega[band][np.argmax(smooth[band])]
    peak_true = omega[band][np.argmax(analytic[band])]
    assert peak_est == pytest.approx(peak_true, rel=0.2)
    # shape: the estimate tracks the analytic PSD (up to a constant) within 25 % in the band
    ratio = smooth[band] / analytic[band]
    assert np.max(np.abs(ratio / np.median(ratio) - 1.0)) < 0.25


def test_kanai_tajimi_rejects_bad_arguments() -> None:
    with pytest.raises(ValueError, match="pga_m_s2 must be finite and > 0"):
        kanai_tajimi(0.0)
    with pytest.raises(ValueError, match="omega_g and zeta_g"):
        kanai_tajimi(1.0, omega_g=-1.0)
    with pytest.raises(ValueError, match="JenningsEnvelope needs"):
        JenningsEnvelope(5.0, 2.0, 0.1)
