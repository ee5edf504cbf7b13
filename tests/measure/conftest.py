"""A small, hand-checkable lab workbook written in tmp_path as .xlsx or as a CSV folder.

Every number below is chosen so the expected estimates can be worked out by hand; the tests
state those hand values next to their assertions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np
import pandas as pd
import pytest

from demcal.measure.workbook import write_workbook
from demcal.units import GRAVITY

G = GRAVITY  # the gravity the estimator assumes


def track_frame(e, drop_height=0.3, fps=500.0, t_release=0.02, g=G):
    """Exact free-fall track (no noise): still until release, impact, rebound, second impact."""
    t1 = math.sqrt(2 * drop_height / g)
    v2 = e * g * t1
    t2 = t1 + 2 * v2 / g
    t = np.arange(0.0, t_release + t2 + 0.02, 1.0 / fps)
    s = t - t_release
    y = np.where(s <= 0, drop_height, drop_height - 0.5 * g * s**2)
    y = np.where(s > t1, v2 * (s - t1) - 0.5 * g * (s - t1) ** 2, y)
    y = np.where(s > t2, e * v2 * (s - t2) - 0.5 * g * (s - t2) ** 2, y)
    return pd.DataFrame({"t_s": t, "y_mm": y * 1e3})


def curve_frame(stiffness_n_per_mm, linear_to_mm, n=21):
    """Linear loading F = k d up to ``linear_to_mm``, then the specimen cracks (force halves)."""
    d = np.linspace(0.0, linear_to_mm, n)
    F = stiffness_n_per_mm * d
    d_after = linear_to_mm + np.array([0.05, 0.1, 0.15, 0.2])
    F_after = 0.5 * F[-1] + 5.0 * (d_after - linear_to_mm)
    return pd.DataFrame({"displacement_mm": np.r_[d, d_after], "force_N": np.r_[F, F_after]})


def base_sheets() -> dict:
    return {
        "meta": {"material": "test segments", "contact_material": "steel",
                 "contact_density_kg_m3": 7850, "contact_poisson": 0.3,
                 "contact_shear_modulus_pa": 8e10, "particle_shear_modulus_pa": 1e7,
                 "box_length_mm": 200, "box_width_mm": 100, "box_height_mm": 250,
                 "plate_lift_speed_mm_s": 100, "fill_count": 500, "lab_room": "B12"},
        "specimens": [
            {"specimen_id": "S1", "length_mm": 24, "diameter_mm": 10, "mass_g": 1.6, "moisture_pct": 9.5, "batch": "A"},
            {"specimen_id": "S2", "length_mm": 25, "diameter_mm": 11, "mass_g": 2.0, "moisture_pct": 10.5, "batch": "A"},
            {"specimen_id": "S3", "length_mm": 26, "diameter_mm": 12, "mass_g": 2.4, "moisture_pct": 11.0, "batch": "B"},
        ],
        "density": [
            {"sample_id": "D1", "mass_g": 10, "volume_before_ml": 50, "volume_after_ml": 61},
            {"sample_id": "D2", "mass_g": 12, "volume_before_ml": 50, "volume_after_ml": 63},
            {"sample_id": "D3", "mass_g": 11, "volume_before_ml": 40, "volume_after_ml": 52},
        ],
        "drop": [
            {"trial_id": "T1", "pair": "particle-steel", "drop_height_mm": 400, "rebound_height_mm": 49,
             "track_file": None, "specimen_id": "S1", "date": pd.Timestamp("2024-05-01"), "operator": "ana", "orientation_deg": 0, "trial_order": 1},
            {"trial_id": "T2", "pair": "particle-steel", "drop_height_mm": 400, "rebound_height_mm": 36,
             "track_file": None, "specimen_id": "S2", "date": pd.Timestamp("2024-05-01"), "operator": "ben", "orientation_deg": 45, "trial_order": 2},
            {"trial_id": "T3", "pair": "particle-steel", "drop_height_mm": 200, "rebound_height_mm": 18,
             "track_file": None, "specimen_id": "S3", "date": pd.Timestamp("2024-05-02"), "operator": "ana", "orientation_deg": 90, "trial_order": 3},
            {"trial_id": "T4", "pair": "particle-steel", "drop_height_mm": 200, "rebound_height_mm": 24.5,
             "track_file": None, "specimen_id": "S1", "date": pd.Timestamp("2024-05-02"), "operator": "ben", "orientation_deg": 0, "trial_order": 4},
            {"trial_id": "T5", "pair": "particle-steel", "drop_height_mm": 300, "rebound_height_mm": 27,
             "track_file": "tracks/t5.csv", "specimen_id": "S2", "date": pd.Timestamp("2024-05-03"), "operator": "ana", "orientation_deg": 45, "trial_order": 5},
            {"trial_id": "T6", "pair": "Particle-Particle", "drop_height_mm": 400, "rebound_height_mm": 36,
             "track_file": None, "specimen_id": "S3", "date": pd.Timestamp("2024-05-03"), "operator": "ben", "orientation_deg": 90, "trial_order": 6},
            {"trial_id": "T7", "pair": "particle-particle", "drop_height_mm": 400, "rebound_height_mm": 64,
             "track_file": None, "specimen_id": "S1", "date": pd.Timestamp("2024-05-03"), "operator": "ana", "orientation_deg": 0, "trial_order": 7},
        ],
        "incline": [
            {"trial_id": "I1", "surface": "particle", "mode": "slide", "angle_deg": 33, "slope_deg": None,
             "release_height_mm": None, "runout_mm": None, "moisture_pct": 10},
            {"trial_id": "I2", "surface": "particle", "mode": "slide", "angle_deg": 34, "slope_deg": None,
             "release_height_mm": None, "runout_mm": None, "moisture_pct": 11},
            {"trial_id": "I3", "surface": "particle", "mode": "slide", "angle_deg": 32, "slope_deg": None,
             "release_height_mm": None, "runout_mm": None, "moisture_pct": 9},
            {"trial_id": "I4", "surface": "steel", "mode": "slide", "angle_deg": 11, "slope_deg": None,
             "release_height_mm": None, "runout_mm": None, "moisture_pct": 10},
            {"trial_id": "I5", "surface": "steel", "mode": "slide", "angle_deg": 12, "slope_deg": None,
             "release_height_mm": None, "runout_mm": None, "moisture_pct": 10},
            {"trial_id": "I6", "surface": "particle", "mode": "roll", "angle_deg": 28, "slope_deg": None,
             "release_height_mm": None, "runout_mm": None, "moisture_pct": 10},
            {"trial_id": "I7", "surface": "particle", "mode": "roll", "angle_deg": 27, "slope_deg": None,
             "release_height_mm": None, "runout_mm": None, "moisture_pct": 10},
            {"trial_id": "I8", "surface": "steel", "mode": "roll", "angle_deg": None, "slope_deg": 30,
             "release_height_mm": 50, "runout_mm": 150, "moisture_pct": 10},
            {"trial_id": "I9", "surface": "steel", "mode": "roll", "angle_deg": None, "slope_deg": 30,
             "release_height_mm": 50, "runout_mm": 200, "moisture_pct": 12},
        ],
        "compression": [
            {"specimen_id": "S1", "axis": "radial", "width_before_mm": 11, "width_after_mm": 11.5,
             "thickness_before_mm": 11, "thickness_after_mm": 10, "curve_file": "curves/c1.csv", "operator": "ana"},
            {"specimen_id": "S2", "axis": "radial", "width_before_mm": 10, "width_after_mm": 10.3,
             "thickness_before_mm": 12, "thickness_after_mm": 10, "curve_file": None, "operator": "ben"},
            {"specimen_id": "S3", "axis": "axial", "width_before_mm": 11, "width_after_mm": 11.2,
             "thickness_before_mm": 25, "thickness_after_mm": 22, "curve_file": "curves/c3.csv", "operator": "ana"},
        ],
        "repose": [
            {"photo_id": "P1", "file": "photos/p1.png", "side": "both", "angle_deg_manual": 35.0, "day": 1},
            {"photo_id": "P2", "file": "photos/p2.png", "side": "left", "angle_deg_manual": 36.0, "day": 2},
        ],
        "notes": [{"note": "balance calibrated", "by": "ana"}],
    }


def write_attachments(root, tracks=None, curves=None, photos=True):
    """Write the track, curve and photo files the base sheets point to."""
    (root / "tracks").mkdir(parents=True, exist_ok=True)
    (root / "curves").mkdir(exist_ok=True)
    (root / "photos").mkdir(exist_ok=True)
    for name, frame in (tracks or {"t5.csv": track_frame(0.4)}).items():
        frame.to_csv(root / "tracks" / name, index=False)
    for name, frame in (curves or {"c1.csv": curve_frame(200.0, 1.0), "c3.csv": curve_frame(100.0, 0.5)}).items():
        frame.to_csv(root / "curves" / name, index=False)
    if photos:
        img = np.zeros((40, 60, 3), np.uint8)
        cv2.fillPoly(img, [np.array([[5, 35], [30, 10], [55, 35]], np.int32)], (200, 200, 200))
        for name in ("p1.png", "p2.png"):
            cv2.imwrite(str(root / "photos" / name), img)


def save(root, sheets, fmt):
    """Write ``sheets`` as ``root/workbook.xlsx`` or as CSVs in ``root``; return the workbook path."""
    root.mkdir(parents=True, exist_ok=True)
    if fmt == "xlsx":
        return write_workbook(sheets, root / "workbook.xlsx")
    return write_workbook(sheets, root)


@dataclass
class StubPhoto:
    """What measure.repose.angle_from_photo returns, for tests without the photo estimator."""

    angle_deg: float
    flanks: dict = field(default_factory=dict)
    base_tilt_deg: float = 0.0


def stub_photo_estimator(angles: dict):
    """A photo estimator returning fixed angles by file name, recording its calls."""
    calls = []

    def estimate(path, side="both", annotate_to=None, max_pixels=None):
        calls.append({"path": path, "side": side, "annotate_to": annotate_to, "max_pixels": max_pixels})
        a = angles[path.name]
        return StubPhoto(a, {"left": a - 1.0, "right": a + 1.0 if side == "both" else None}, 0.5)

    estimate.calls = calls
    return estimate


@pytest.fixture(params=["xlsx", "csv"])
def fmt(request):
    return request.param


@pytest.fixture
def campaign(tmp_path, fmt):
    """``make(edit=None)`` writes the base workbook (after ``edit(sheets)``) and returns its path."""
    def make(edit=None, **attachments):
        sheets = base_sheets()
        if edit is not None:
            edit(sheets)
        root = tmp_path / "campaign"
        write_attachments(root, **attachments)
        return save(root, sheets, fmt)
    return make
