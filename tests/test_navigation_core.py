"""Navigation cores against analytic cases: rotations, INS mechanisation, Kalman, homography, 3-D lines."""
import math

import numpy as np
import pytest

from navigation.camera import PinholeCamera
from navigation.flight import fly, plan_route, true_increments
from navigation.homography import (fit_homography_lines, map_segments, plane_homography, ransac_homography_lines,
                                   trimmed_homography_lines)
from navigation.imu import ImuModel
from navigation.ins import NavState, ins_step, mechanise
from navigation.kalman import N_STATES, KalmanFilter, ins_error_dynamics, kf_predict, kf_update
from navigation.reconstruction import reconstruct_line
from navigation.rotations import body_to_world, exp_so3, log_so3


def test_exp_log_roundtrip_and_orthonormal():
    rng = np.random.default_rng(0)
    phi = rng.normal(0, 1.0, (50, 3))
    R = exp_so3(phi)
    assert np.allclose(R @ np.swapaxes(R, -1, -2), np.eye(3), atol=1e-12)
    assert np.allclose(log_so3(R), phi, atol=1e-9)
    assert np.allclose(exp_so3(np.array([0, 0, math.pi / 2])) @ [1, 0, 0], [0, 1, 0], atol=1e-12)


def test_body_to_world_conventions():
    # heading 90° points the nose to +y; climb lifts it; bank right lowers the right wing (−y body → down)
    assert np.allclose(body_to_world(math.pi / 2, 0, 0) @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    assert body_to_world(0, 0.1, 0)[2, 0] > 0
    assert (body_to_world(0, 0, 0.2) @ [0, -1, 0])[2] < 0


def test_mechanisation_reproduces_a_closed_form_level_turn():
    """Constant-rate level turn at V: increments in closed form, positions on the analytic circle."""
    V, w, dt, T = 250.0, math.radians(3.0), 1 / 200, 60.0
    n = int(T / dt)
    g = 9.80665
    # in the turning body frame the specific force is constant: centripetal V w to the left, g up.
    # Its exact increment over dt, expressed in the mid-interval body frame, is the horizontal part
    # times sinc(w dt / 2) (chord of the arc) and the vertical part unchanged
    x = w * dt / 2
    dtheta = np.tile([0.0, 0.0, w * dt], (n, 1))
    dv = np.tile([0.0, V * w * dt * math.sin(x) / x, g * dt], (n, 1))
    s0 = NavState(0.0, np.zeros(3), np.array([V, 0.0, 0.0]), np.eye(3))
    p, v, R = mechanise(s0, dtheta, dv, dt)
    t = np.arange(n + 1) * dt
    r = V / w
    p_ref = np.column_stack([r * np.sin(w * t), r * (1 - np.cos(w * t)), np.zeros_like(t)])
    v_ref = np.column_stack([V * np.cos(w * t), V * np.sin(w * t), np.zeros_like(t)])
    assert np.abs(p - p_ref).max() < 0.01
    assert np.abs(v - v_ref).max() < 1e-3
    # the step form agrees with the vectorised one
    s = s0
    for k in range(200):
        s = ins_step(s, dtheta[k], dv[k], dt)
    assert np.allclose(s.p, p[200], atol=1e-9) and np.allclose(s.R, R[200], atol=1e-12)


def test_perfect_imu_reproduces_the_flight_and_biases_drift_as_expected():
    rng = np.random.default_rng(3)
    route = plan_route(length_m=20_000, speed_mps=250, rate_hz=100, turns=2, max_bank_deg=30, rng=rng)
    fl = fly(route, lambda x, y: 80 * np.sin(x / 2000.0), agl_min_m=200, agl_max_m=400, rng=rng)
    dth, dv = true_increments(fl)
    s0 = NavState(0.0, fl.p[0], fl.v[0], fl.R[0])
    p, v, R = mechanise(s0, dth, dv, fl.dt)
    assert np.abs(p - fl.p).max() < 1e-4
    assert fl.agl.min() > 150
    # a pure accelerometer bias b along world x on a straight level leg gives b t² / 2 (first seconds)
    b = 0.01
    dv_b = dv + np.einsum("kji,j->ki", fl.R[:-1], [b, 0, 0]) * fl.dt
    p2, _, _ = mechanise(s0, dth, dv_b, fl.dt)
    k = 500
    assert p2[k, 0] - fl.p[k, 0] == pytest.approx(0.5 * b * (k * fl.dt) ** 2, rel=0.02)


def test_imu_errors_units():
    m = ImuModel(gyro_bias_deg_h=5.0, accel_bias_mg=3.0)
    s = m.si()
    assert s["gyro_bias"] == pytest.approx(math.radians(5) / 3600)
    assert s["accel_bias"] == pytest.approx(3e-3 * 9.80665)
    with pytest.raises(ValueError, match="accel_bias_mg"):
        ImuModel(accel_bias_mg=-1)


def test_kalman_sequential_updates_equal_the_batch_solution():
    rng = np.random.default_rng(1)
    n = 6
    x0 = rng.normal(size=n)
    A = rng.normal(size=(n, n))
    P0 = A @ A.T + n * np.eye(n)
    Hs = [rng.normal(size=(3, n)) for _ in range(3)]
    Rs = [np.diag(rng.uniform(0.5, 2, 3)) for _ in range(3)]
    zs = [rng.normal(size=3) for _ in range(3)]
    kf = KalmanFilter(x0, P0)
    x, P = x0, P0
    for z, H, R in zip(zs, Hs, Rs):
        kf.update(z, H, R)
        x, P, _, _ = kf_update(x, P, z, H, R)
    # batch: information form
    info = np.linalg.inv(P0) + sum(H.T @ np.linalg.solve(R, H) for H, R in zip(Hs, Rs))
    P_b = np.linalg.inv(info)
    x_b = P_b @ (np.linalg.solve(P0, x0) + sum(H.T @ np.linalg.solve(R, z) for z, H, R in zip(zs, Hs, Rs)))
    assert np.allclose(x, x_b, atol=1e-9) and np.allclose(P, P_b, atol=1e-9)
    assert np.allclose(kf.x, x) and np.allclose(kf.P, P)
    F = np.eye(n) + 0.1 * rng.normal(size=(n, n))
    Q = 0.01 * np.eye(n)
    kf.predict(F, Q)
    xp, Pp = kf_predict(x, P, F, Q)
    assert np.allclose(kf.x, xp) and np.allclose(kf.P, Pp)


def test_ins_error_dynamics_predicts_a_bias_drift():
    # velocity error from an accelerometer bias state: δv = R b t, δp = R b t² / 2
    F, Q = ins_error_dynamics(np.array([0, 0, 9.8]), np.eye(3), 0.01, accel_vrw=0.0, gyro_arw=0.0)
    x = np.zeros(N_STATES)
    x[9] = 0.02
    for _ in range(1000):
        x = F @ x
    assert x[3] == pytest.approx(0.02 * 10, rel=1e-6)
    assert x[0] == pytest.approx(0.02 * 100 / 2, rel=1e-3)
    assert np.allclose(Q, 0)


def _two_views():
    cam = PinholeCamera(width=640, height=480, hfov_deg=50, depression_deg=15)
    R1 = body_to_world(0.1, 0.0, 0.02)
    R2 = body_to_world(0.12, 0.01, 0.0)
    pose1 = cam.pose(np.array([0.0, 0.0, 400.0]), R1)
    pose2 = cam.pose(np.array([30.0, 4.0, 398.0]), R2)
    return cam, pose1, pose2


def test_homography_of_a_known_plane_motion():
    cam, pose1, pose2 = _two_views()
    rng = np.random.default_rng(5)
    # segments on the ground plane z = 20 m, in view of both cameras
    X = np.column_stack([rng.uniform(900, 2500, (12, 1)), rng.uniform(-500, 500, (12, 1)), np.full((12, 1), 20.0)])
    Y = X + np.column_stack([rng.uniform(-150, 150, (12, 2)), np.zeros((12, 1))])
    H = plane_homography(cam.K, pose1, pose2, [0, 0, 1], 20.0)
    u1a, _ = cam.project(X, pose1)
    u1b, _ = cam.project(Y, pose1)
    u2a, _ = cam.project(X, pose2)
    u2b, _ = cam.project(Y, pose2)
    seg1 = np.column_stack([u1a, u1b])
    seg2 = np.column_stack([u2a, u2b])
    assert np.allclose(map_segments(H, seg1), seg2, atol=1e-6)
    # fitted from the lines alone, the second image's segments shortened and shifted along themselves
    t = rng.uniform(0.1, 0.3, (12, 1))
    seg2_cut = np.column_stack([u2a + t * (u2b - u2a), u2b - t * (u2b - u2a)])
    Hf = fit_homography_lines(seg1, seg2_cut)
    assert np.allclose(map_segments(Hf, seg1), seg2, atol=1e-5)
    # robust fit with three wrong pairs
    bad = seg2_cut.copy()
    bad[:3] += 40.0
    Hr, inl = ransac_homography_lines(seg1, bad, threshold_px=1.0)
    assert inl.sum() == 9 and not inl[:3].any()
    assert np.allclose(map_segments(Hr, seg1[3:]), seg2[3:], atol=1e-4)
    Ht, inl = trimmed_homography_lines(seg1, bad, threshold_px=1.0)
    assert inl.sum() == 9 and not inl[:3].any()
    assert np.allclose(map_segments(Ht, seg1[3:]), seg2[3:], atol=1e-4)


def test_reconstruction_of_a_known_line_from_exact_poses():
    cam = PinholeCamera(width=640, height=480, hfov_deg=50, depression_deg=12)
    a = np.array([2500.0, -200.0, 35.0])
    b = np.array([2300.0, 300.0, 40.0])
    poses = [cam.pose(np.array([25.0 * k, 2.0 * k, 400.0 - k]), body_to_world(0.01 * k, 0.0, 0.0)) for k in range(8)]
    segs = []
    for k, pose in enumerate(poses):
        ua, _ = cam.project(a, pose)
        ub, _ = cam.project(b, pose)
        # each view sees a different part of the segment (the endpoints do not correspond)
        f0, f1 = 0.05 * (k % 3), 1.0 - 0.04 * (k % 2)
        segs.append(np.concatenate([ua + f0 * (ub - ua), ua + f1 * (ub - ua)]))
    line = reconstruct_line(cam.K, np.array(segs), poses)
    assert line is not None and line.rms_px < 1e-6
    u = (b - a) / np.linalg.norm(b - a)
    for p in (line.a, line.b):
        off = (p - a) - ((p - a) @ u) * u
        assert np.linalg.norm(off) < 1e-4
    assert abs(abs(line.direction @ u) - 1) < 1e-9
    # the reconstructed extent is inside the true segment and covers most of it
    s = sorted([(line.a - a) @ u, (line.b - a) @ u])
    assert s[0] >= -1e-3 and s[1] <= np.linalg.norm(b - a) + 1e-3 and s[1] - s[0] > 0.85 * np.linalg.norm(b - a)


def _grid_map(spacing, n=6):
    from navigation.world import KINDS, LineMap

    segs = []
    for k in range(n):
        for j in range(n):
            segs.append([k * spacing, j * spacing, k * spacing, (j + 1) * spacing])       # x = const
            segs.append([j * spacing, k * spacing, (j + 1) * spacing, k * spacing])       # y = const
    segs = np.array(segs, float)
    return LineMap(segs, np.full(len(segs), KINDS.index("field_edge")))


def test_map_matching_recovers_a_known_shift_and_refuses_ambiguity():
    from navigation.map_matching import match_to_reference, normal_distances

    ref = _grid_map(170.0)
    rng = np.random.default_rng(2)
    pick = rng.choice(len(ref), 12, replace=False)
    ins_error = np.array([12.0, -7.0])
    lines = ref.segments[pick] + np.tile(ins_error, 2) + rng.normal(0, 0.5, (12, 4))
    m = match_to_reference(lines, ref, gate_m=60.0)
    assert m.status == "ok" and len(m.pairs) == 12
    assert np.allclose(m.shift, -ins_error, atol=2.5)
    # each line is paired with its own reference line (a collinear neighbour piece is the same line)
    for i, j in m.pairs:
        assert np.abs(normal_distances(ref.segments[pick[i]].reshape(2, 2), np.tile(ref.segments[j], (2, 1)))).max() < 1e-9
    d = normal_distances(lines[:, :2] + m.shift, ref.segments[[j for _, j in m.pairs]])
    assert np.abs(d).max() < 4.0
    # a regular grid 60 m apart seen through a gate of 100 m: rival shifts exist, no fix ...
    ref2 = _grid_map(60.0)
    pick2 = rng.choice(len(ref2), 12, replace=False)
    lines2 = ref2.segments[pick2] + np.tile(ins_error, 2)
    assert match_to_reference(lines2, ref2, gate_m=100.0).status.startswith("ambiguous")
    # ... unless the INS's own uncertainty (3 σ = 15 m) rules the rivals out
    ok = match_to_reference(lines2, ref2, gate_m=100.0, prior_sigma_m=5.0)
    assert ok.status == "ok" and np.allclose(ok.shift, -ins_error, atol=2.5)
    # lines of one direction only do not fix a 2-D position
    one_dir = np.array([s for s in ref.segments if s[0] == s[2]])[:8] + np.tile(ins_error, 2)
    assert "direction" in match_to_reference(one_dir, ref, gate_m=60.0).status
