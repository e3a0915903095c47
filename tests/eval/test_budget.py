"""E7's truth substitutions (`experiments.budget`) on a synthetic trace whose every error is
known: each substitution takes out exactly its own term."""

from __future__ import annotations

import math

import numpy as np
import pytest

from roadpreview.compensation import compensate, heave_term_px
from roadpreview.eval.experiments.budget import (
    TERMS,
    frame_truth,
    residual_std,
    substitute,
    variants,
)
from roadpreview.eval.runner import Trace

F = 700.0
FPS = 30.0


def _case() -> tuple[dict[str, np.ndarray], Trace]:
    t = np.arange(0.0, 12.0, 1.0 / FPS)
    w = 2.0 * math.pi * 1.3
    phi = np.radians(0.4) * np.sin(w * t)
    z = 0.01 * np.sin(w * t + 0.5)  # zero-mean: its 3 s running mean is ~0
    d = 15.0 + 0.2 * np.sin(0.3 * t)
    row = 380.0 + 2.0 * np.sin(2.0 * math.pi * 0.9 * t)  # the lead's own motion
    y_img = row + F * np.tan(phi) + F * z / d  # what the camera sees
    truth = {
        "frame_t_s": t,
        "cam_pitch_rad": phi,
        "cam_z_m": z,
        "lead_distance_m": d,
        "lead_rear_px": np.stack([np.full_like(t, 640.0), y_img], axis=1),
        "ego_speed_m_s": np.full_like(t, 15.0),
    }
    # the product: pitch off by a 2 Hz wobble, heave 30 % short, distance 10 % long,
    # the row off by a 0.5 px 3 Hz jitter; one frame without a lead
    phi_est = phi + np.radians(0.02) * np.sin(2.0 * math.pi * 2.0 * t)
    d_est = 1.1 * d
    heave_px = heave_term_px(0.7 * z, d_est, F)
    y = y_img + 0.5 * np.sin(2.0 * math.pi * 3.0 * t)
    y[100] = np.nan
    y_c = compensate(y, phi_est, F, heave_px)
    n = t.size
    cols = {
        "t": t,
        "y": y,
        "y_c": y_c,
        "phi": phi_est,
        "heave_px": heave_px,
        "lead_distance_m": d_est,
        "target_changed": np.zeros(n, dtype=np.int64),
        "traj_y_c": y_c,
        "traj_y_c_left": y_c - 1.0,
        "traj_y_c_right": y_c + 1.0,
        "traj_compensation_px": F * np.tan(phi_est) + heave_px,
        "traj_valid": np.isfinite(y_c).astype(np.float64),
    }
    return truth, Trace("fused-kalman", cols, focal_px=F)


def test_every_term_substituted_leaves_no_residual() -> None:
    truth, tr = _case()
    ft = frame_truth(truth, tr.t, F)
    full = substitute(tr, ft, TERMS)
    r = full["traj_y_c"] - ft.y_c
    ok = np.isfinite(tr["y"])
    assert np.abs(r[ok]).max() < 1e-9
    assert np.isnan(full["traj_y_c"][~ok]).all()  # a frame without a lead stays without
    # the halves move with the centre, the compensation term is the true one
    assert np.allclose(full["traj_y_c_left"][ok], full["traj_y_c"][ok] - 1.0)
    assert full["traj_valid"][100] == 0


def test_each_term_alone_takes_out_its_own_error() -> None:
    """Product residual = pitch + heave + distance + tracking errors; with the pitch true
    the pitch's 2 Hz wobble (f tan 0.02 deg = 0.24 px) is gone and the rest is unchanged."""
    truth, tr = _case()
    ft = frame_truth(truth, tr.t, F)
    base = tr["traj_y_c"] - ft.y_c
    true_phi = np.radians(0.4) * np.sin(2.0 * math.pi * 1.3 * tr.t)
    pitch_err = F * (np.tan(tr["phi"]) - np.tan(true_phi))
    r_pitch = substitute(tr, ft, ("pitch",))["traj_y_c"] - ft.y_c
    assert np.nanmax(np.abs(r_pitch - (base + pitch_err))) < 1e-9
    r_track = substitute(tr, ft, ("tracking",))["traj_y_c"] - ft.y_c
    jitter = 0.5 * np.sin(2.0 * math.pi * 3.0 * tr.t)
    assert np.nanmax(np.abs(r_track - (base - jitter))) < 1e-9
    # heave and distance together: the term is the truth's
    r_hd = substitute(tr, ft, ("heave", "distance"))["traj_y_c"] - ft.y_c
    heave_err = tr["heave_px"] - heave_term_px(truth["cam_z_m"], truth["lead_distance_m"], F)
    mid = (tr.t > 2.0) & (tr.t < 10.0)  # (the truth's heave: less its centred 3 s mean)
    assert np.nanmax(np.abs(r_hd - (base + heave_err))[mid]) < 0.03


def test_the_residual_std_falls_as_terms_are_substituted() -> None:
    truth, tr = _case()
    ft = frame_truth(truth, tr.t, F)
    med = {
        name: float(np.nanmedian(residual_std(substitute(tr, ft, terms), ft)))
        for name, terms in variants().items()
    }
    assert med["product"] > med["+ pitch"] > med["+ pitch + heave + distance + tracking"]
    assert med["+ pitch + heave + distance + tracking"] == pytest.approx(0.0, abs=1e-9)
    assert med["tracking only"] < med["product"]
