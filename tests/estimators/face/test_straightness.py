"""Straightness and creep of the face line in closed form, and from a truth_pans table."""

from __future__ import annotations

import numpy as np

from estimators.face.straightness import face_drift, mat_ft, straightness


def test_straightness_of_a_bent_line_in_closed_form():
    """Three pans at y = -1, 0, 1 with the middle one h ahead: the best-fit line is x = h / 3, the deviations
    -h/3, 2h/3, -h/3, so RMS h sqrt(2) / 3 and max 2h / 3, whatever straight line (tilt, offset) they sit on."""
    h = 0.09
    y = np.array([-1.0, 0.0, 1.0]) * 1.8 + 100.0
    for tilt, offset in ((0.0, 0.0), (0.02, 5.0), (-0.3, -1.0)):
        rms, worst = straightness(np.array([0.0, h, 0.0]) + offset + tilt * y, y)
        np.testing.assert_allclose([rms, worst], [h * np.sqrt(2) / 3, 2 * h / 3], rtol=1e-12)
    rms, worst = straightness(np.stack([0.5 + 0.1 * y, np.array([0.0, h, 0.0])]), y)  # lines along a leading axis
    np.testing.assert_allclose([rms, worst], [[0.0, h * np.sqrt(2) / 3], [0.0, 2 * h / 3]], atol=1e-12)


def test_face_drift_from_a_truth_pans_table():
    """Four pans in the face frame F of a 30 deg face written as a log's truth_pans rows (ENU), updated at different
    times: at t = 10 all are a web deeper and 0.05 m towards the tailgate, pan 2 also 0.03 m ahead; the drift at
    t = 5 (before any update) is nil, at t = 10 the creep is 0.05 m and the straightness that of pan 2's step."""
    azimuth = np.radians(30.0)
    n = 4
    start = np.column_stack([np.zeros(n), 1.8 * np.arange(n), np.zeros(n)])
    later = start + [1.0, 0.05, 0.0]
    later[2, 0] += 0.03
    p_f = np.concatenate([start, later[:2], later[2:]])
    t = np.array([0.0] * n + [8.0] * 2 + [10.0] * 2)
    p_t = p_f @ mat_ft(azimuth)  # F to t: the transpose of C_t^F, on row vectors
    pans = {"t": t, "pan": np.array([0, 1, 2, 3, 0, 1, 2, 3]), "p_t_e": p_t[:, 0], "p_t_n": p_t[:, 1],
            "p_t_u": p_t[:, 2]}
    drift = face_drift(pans, np.array([5.0, 10.0, 20.0]), n, azimuth)
    want_rms, want_max = straightness(later[:, 0], later[:, 1])
    np.testing.assert_allclose(drift.straightness_rms, [0.0, want_rms, want_rms], atol=1e-12)
    np.testing.assert_allclose(drift.straightness_max, [0.0, want_max, want_max], atol=1e-12)
    np.testing.assert_allclose(drift.creep, [0.0, 0.05, 0.05], atol=1e-12)
    np.testing.assert_allclose(drift.creep_tailgate, [0.0, 0.05, 0.05], atol=1e-12)
    assert want_rms > 0.01
