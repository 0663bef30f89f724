"""Kalman filter / RTS smoother against batch Gaussian conditioning; Kalman integration."""
import numpy as np
import pytest
from scipy.linalg import solve_discrete_lyapunov

from restore.integration import integrate
from restore.integration.kalman import KalmanSmoother, kalman_smooth, oscillator_model

DT = 0.4e-3
TAUS = [7.4e-3, 14.8e-3, 22.2e-3]


def small_model(seed=0, n=4, m=2):
    rng = np.random.default_rng(seed)
    F = 0.4 * rng.normal(size=(n, n))
    H = rng.normal(size=(m, n))
    A = rng.normal(size=(n, n))
    Q = 0.1 * A @ A.T + 0.01 * np.eye(n)
    return F, H, Q, np.array([0.3, 0.5]), rng.normal(size=n), np.eye(n)


def batch_posterior(z, F, H, Q, R, x0, P0):
    """Posterior of all states by conditioning the joint Gaussian (analytic reference)."""
    T, n = z.shape[0], F.shape[0]
    Ps = [P0]
    for _ in range(1, T):
        Ps.append(F @ Ps[-1] @ F.T + Q)
    C = np.zeros((n * T, n * T))
    for i in range(T):
        for j in range(i, T):
            c = np.linalg.matrix_power(F, j - i) @ Ps[i]
            C[j * n:(j + 1) * n, i * n:(i + 1) * n] = c
            C[i * n:(i + 1) * n, j * n:(j + 1) * n] = c.T
    mu = np.concatenate([np.linalg.matrix_power(F, k) @ x0 for k in range(T)])
    rows, vals, rv = [], [], []
    for k in range(T):
        for i in range(H.shape[0]):
            if np.isfinite(z[k, i]):
                h = np.zeros(n * T)
                h[k * n:(k + 1) * n] = H[i]
                rows.append(h)
                vals.append(z[k, i])
                rv.append(R[i])
    Hb = np.array(rows)
    S = Hb @ C @ Hb.T + np.diag(rv)
    post = mu + C @ Hb.T @ np.linalg.solve(S, np.array(vals) - Hb @ mu)
    cov = C - C @ Hb.T @ np.linalg.solve(S, Hb @ C)
    return post.reshape(T, n), np.diag(cov).reshape(T, n)


def test_smoother_equals_batch_conditioning_with_missing_data():
    F, H, Q, R, x0, P0 = small_model()
    z = np.random.default_rng(1).normal(size=(30, 2))
    z[5, 0] = np.nan
    z[10:13] = np.nan
    ref_x, ref_v = batch_posterior(z, F, H, Q, R, x0, P0)
    for chk in (1, 7, 100):
        xs, vs = KalmanSmoother(F, H, Q, R, x0, P0).smooth(z, checkpoint=chk)
        np.testing.assert_allclose(xs, ref_x, atol=1e-10)
        np.testing.assert_allclose(vs, ref_v, atol=1e-10)


def test_function_and_class_agree_and_filter_end():
    F, H, Q, R, x0, P0 = small_model(2)
    z = np.random.default_rng(3).normal(size=(25, 2))
    ks = KalmanSmoother(F, H, Q, R, x0, P0)
    xs, vs = ks.smooth(z)
    xf, vf = kalman_smooth(z, F=F, H=H, Q=Q, R=R, x0=x0, P0=P0)
    np.testing.assert_array_equal(xs, xf)
    np.testing.assert_array_equal(vs, vf)
    x_filt, v_filt = ks.filter(z)
    np.testing.assert_allclose(x_filt[-1], xs[-1], atol=1e-12)   # last step: filter = smoother
    np.testing.assert_allclose(v_filt[-1], vs[-1], atol=1e-12)
    assert np.all(vs <= v_filt + 1e-12)                          # smoothing never hurts


def test_kalman_shape_errors():
    F, H, Q, R, x0, P0 = small_model()
    with pytest.raises(ValueError, match="^H"):
        KalmanSmoother(F, H[:, :3], Q, R, x0, P0)
    with pytest.raises(ValueError, match="^z"):
        KalmanSmoother(F, H, Q, R, x0, P0).smooth(np.zeros((5, 3)))


def test_oscillator_model_stationary_variance():
    F, Q, h = oscillator_model([50.0, 80.0], [0.5, 1.0], [2.0, 3.0], DT, order=2)
    P = solve_discrete_lyapunov(F, Q)
    np.testing.assert_allclose([P[2, 2], P[6, 6]], [2.0, 3.0], rtol=1e-8)
    assert h.sum() == 2
    # eigenvalues rotate at 2 pi f dt
    ang = np.sort(np.abs(np.angle(np.linalg.eigvals(F))))
    np.testing.assert_allclose(ang[[0, -1]], 2 * np.pi * np.array([50.0, 80.0]) * DT, rtol=1e-6)


def test_kalman_integration_of_noisy_lines():
    t = np.arange(3000) * DT
    theta = lambda x: np.sin(2 * np.pi * 53.0 * x + 0.2) + 0.4 * np.sin(2 * np.pi * 106.0 * x)
    rng = np.random.default_rng(4)
    diffs = [theta(t + tau) - theta(t) + 0.02 * rng.standard_normal(t.size) for tau in TAUS]
    est = integrate(diffs, TAUS, DT, method="kalman")
    e = est - theta(t)
    assert np.std(e) < 0.01
    est2 = integrate(diffs, TAUS, DT, method="kalman", frequencies_hz=[53.0, 106.0])
    assert np.std(est2 - theta(t)) < 0.02
