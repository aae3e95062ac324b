"""Tests of mascore.kalman against filterpy, the textbook formulas and Monte Carlo."""

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from mascore import agents, kalman, noise


def _random_spd(rng, m):
    M = rng.standard_normal((m, m))
    return M @ M.T + m * np.eye(m)


def test_matches_filterpy_over_a_run():
    """Same model, same measurements: our predict/update equals filterpy's KalmanFilter."""
    rng = np.random.default_rng(1)
    model = agents.double_integrator(2, 0.1)
    H = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])
    Q, R = 0.2 * np.eye(4), 0.5 * np.eye(2)
    kf = KalmanFilter(dim_x=4, dim_z=2, dim_u=2)
    kf.F, kf.B, kf.H, kf.Q, kf.R = model.A, model.B, H, Q, R
    kf.x, kf.P = np.zeros(4), 10 * np.eye(4)
    x, P = np.zeros(4), 10 * np.eye(4)
    for _ in range(30):
        u = rng.standard_normal(2)
        z = rng.standard_normal(2)
        kf.predict(u=u)
        kf.update(z)
        x, P = kalman.predict(x, P, model.A, Q, B=model.B, u=u)
        x, P = kalman.update(x, P, z, H, R)
        np.testing.assert_allclose(x, kf.x, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(P, kf.P, rtol=1e-10, atol=1e-12)


def test_joseph_equals_textbook_form_for_optimal_gain():
    """With the optimal gain, Joseph form equals (I - K H) P."""
    rng = np.random.default_rng(2)
    P, R = _random_spd(rng, 5), _random_spd(rng, 3)
    H = rng.standard_normal((3, 5))
    _, P_post = kalman.update(np.zeros(5), P, np.zeros(3), H, R)
    K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
    np.testing.assert_allclose(P_post, (np.eye(5) - K @ H) @ P, rtol=1e-10, atol=1e-10)
    # information form: P+^{-1} = P^{-1} + H^T R^{-1} H
    np.testing.assert_allclose(np.linalg.inv(P_post), np.linalg.inv(P) + H.T @ np.linalg.solve(R, H), rtol=1e-9)


def test_batched_equals_loop():
    rng = np.random.default_rng(3)
    xs = rng.standard_normal((6, 4))
    Ps = np.stack([_random_spd(rng, 4) for _ in range(6)])
    zs = rng.standard_normal((6, 2))
    H, R = rng.standard_normal((2, 4)), np.eye(2)
    xb, Pb = kalman.update(xs, Ps, zs, H, R)
    for i in range(6):
        xi, Pi = kalman.update(xs[i], Ps[i], zs[i], H, R)
        np.testing.assert_allclose(xb[i], xi, rtol=1e-12)
        np.testing.assert_allclose(Pb[i], Pi, rtol=1e-12)


def test_covariance_stays_symmetric_positive_definite():
    rng = np.random.default_rng(4)
    F = rng.standard_normal((4, 4))
    x, P = np.zeros(4), np.eye(4)
    for _ in range(50):
        x, P = kalman.predict(x, P, F, 0.01 * np.eye(4))
        x, P = kalman.update(x, P, rng.standard_normal(1), rng.standard_normal((1, 4)), np.eye(1))
        np.testing.assert_array_equal(P, P.T)
        assert np.linalg.eigvalsh(P).min() > 0


def test_nees_is_chi_square_consistent_over_monte_carlo():
    """A correctly tuned filter's average NEES lies in the 95% chi-square interval."""
    rng = np.random.default_rng(5)
    model = agents.double_integrator(1, 0.5)
    H, Q, R = np.array([[1.0, 0.0]]), 0.1 * np.eye(2), np.array([[0.5]])
    runs, steps = 200, 40
    x_true = noise.gaussian(rng, np.eye(2), runs)
    x_hat, P = np.zeros((runs, 2)), np.broadcast_to(np.eye(2), (runs, 2, 2))
    for _ in range(steps):
        x_true = x_true @ model.A.T + noise.gaussian(rng, Q, runs)
        z = x_true @ H.T + noise.gaussian(rng, R, runs)
        x_hat, P = kalman.predict(x_hat, P, model.A, Q)
        x_hat, P = kalman.update(x_hat, P, z, H, R)
    avg = kalman.nees(x_true - x_hat, P).mean()
    low, high = kalman.nees_interval(2, runs)
    assert low < avg < high
    # and an over-confident filter (P shrunk 4x) is caught
    assert kalman.nees(x_true - x_hat, P / 4).mean() > high


def test_nees_interval_brackets_dof():
    low, high = kalman.nees_interval(4, 50)
    assert low < 4 < high
    assert kalman.nees_interval(4, 500)[1] - kalman.nees_interval(4, 500)[0] < high - low


def test_bad_inputs():
    with pytest.raises(ValueError, match="Q"):
        kalman.predict(np.zeros(2), np.eye(2), np.eye(2), -np.eye(2))
    with pytest.raises(ValueError, match="positive definite"):
        kalman.update(np.zeros(2), np.eye(2), np.zeros(1), np.ones((1, 2)), np.zeros((1, 1)))
    with pytest.raises(ValueError, match="H"):
        kalman.update(np.zeros(2), np.eye(2), np.zeros(1), np.ones((1, 3)), np.eye(1))
    with pytest.raises(ValueError, match="P"):
        kalman.predict(np.zeros(2), np.eye(3), np.eye(2), np.eye(2))
    with pytest.raises(ValueError, match="symmetric"):
        kalman.predict(np.zeros(2), np.eye(2), np.eye(2), np.array([[1.0, 0.5], [0.0, 1.0]]))


def test_run_filter_equals_a_loop_of_checked_steps_bit_for_bit():
    """run_filter checks once and loops on the kernels: same numbers as predict/update, step by step."""
    import numpy as np

    from mascore import agents, kalman

    rng = np.random.default_rng(3)
    F = agents.double_integrator(2, 0.1).A
    H, Q, R = np.eye(2, 4), 0.01 * np.eye(4), 0.25 * np.eye(2)
    z = rng.standard_normal((50, 3, 2))  # 50 steps of a batch of 3 filters
    x0, P0 = np.zeros((3, 4)), np.broadcast_to(np.eye(4), (3, 4, 4))
    xs, Ps = kalman.run_filter(x0, P0, z, F, Q, H, R)
    x, P = x0, P0
    for k in range(z.shape[0]):
        x, P = kalman.predict(x, P, F, Q)
        x, P = kalman.update(x, P, z[k], H, R)
        assert np.array_equal(xs[k], x) and np.array_equal(Ps[k], P)
    assert np.all(np.linalg.eigvalsh(Ps) > 0)


def test_run_filter_refuses_bad_input_by_name():
    import numpy as np
    import pytest

    from mascore import kalman

    good = dict(x0=np.zeros(2), P0=np.eye(2), z=np.zeros((4, 1)), F=np.eye(2), Q=0.1 * np.eye(2),
                H=np.array([[1.0, 0.0]]), R=np.eye(1))
    for name, bad in (("z", np.full((4, 1), np.nan)), ("P0", -np.eye(2)), ("R", np.zeros((1, 1))),
                      ("z", np.zeros((4, 2)))):
        with pytest.raises(ValueError, match=name):
            kalman.run_filter(**(good | {name: bad}))


@pytest.mark.parametrize("equal", [True, False])
def test_batch_with_shared_covariance_equals_a_loop_of_filters(equal):
    """The shared-covariance shortcut of a batch (one covariance and gain) gives what each filter gives alone."""
    rng = np.random.default_rng(3)
    n, q, B = 6, 3, 5
    F = np.eye(n) + 0.05 * rng.standard_normal((n, n))
    G = rng.standard_normal((n, n))
    Q, H, R = 0.1 * G @ G.T + 0.01 * np.eye(n), rng.standard_normal((q, n)), np.eye(q)
    P0 = np.broadcast_to(2.0 * np.eye(n), (B, n, n)).copy()
    if not equal:
        P0[0] *= 3.0
    X, Z = rng.standard_normal((B, n)), rng.standard_normal((2, B, q))
    x, P = X, P0
    for z in Z:
        x, P = kalman.update(*kalman.predict(x, P, F, Q), z, H, R)
    for b in range(B):
        xb, Pb = X[b], P0[b]
        for z in Z:
            xb, Pb = kalman.update(*kalman.predict(xb, Pb, F, Q), z[b], H, R)
        np.testing.assert_allclose(x[b], xb, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(P[b], Pb, rtol=1e-12, atol=1e-13)


# ----------------------------------------------------------------------------
# LinearGaussianModel: checked once, read-only, thread-safe steps
# ----------------------------------------------------------------------------


def _filter_run(seed, n_steps=50, model=None):
    """One filter of 4 states and 2 measurements with its own model and data; all its means and covariances."""
    rng = np.random.default_rng(seed)
    F = np.eye(4) + 0.05 * rng.standard_normal((4, 4))
    Q, R = 0.01 * _random_spd(rng, 4), _random_spd(rng, 2)
    H, B = rng.standard_normal((2, 4)), rng.standard_normal((4, 1))
    model = kalman.LinearGaussianModel(F, Q, H, R, B=B) if model is None else model
    m, q, p = model.n_states, model.n_measurements, model.B.shape[-1]
    x, P = model.check_state(rng.standard_normal(m), _random_spd(rng, m))
    out = []
    for _ in range(n_steps):
        x, P = kalman.predict(x, P, model, rng.standard_normal(p))
        x, P = kalman.update(x, P, rng.standard_normal(q), model)
        out.append((x, P))
    return out


@pytest.fixture
def frequent_switching():
    """Threads switch every 10 us instead of every 5 ms: interleavings a shared state would not survive."""
    import sys

    before = sys.getswitchinterval()
    sys.setswitchinterval(1e-5)
    yield
    sys.setswitchinterval(before)


def test_eight_threads_give_the_serial_results_bit_for_bit(frequent_switching):
    """Independent filters in 8 threads at once: no shared state, so each gives what it gives alone."""
    from concurrent.futures import ThreadPoolExecutor

    seeds = list(range(16))
    serial = [_filter_run(s) for s in seeds]
    with ThreadPoolExecutor(max_workers=8) as pool:
        threaded = list(pool.map(_filter_run, seeds))
    for run_s, run_t in zip(serial, threaded):
        for (xs, Ps), (xt, Pt) in zip(run_s, run_t):
            assert xs.tobytes() == xt.tobytes() and Ps.tobytes() == Pt.tobytes()


def test_eight_threads_on_the_plain_array_functions_and_one_shared_model(frequent_switching):
    """The plain-array form from 8 threads (it once raised 'deque mutated during iteration'), and one model shared."""
    from concurrent.futures import ThreadPoolExecutor

    rng = np.random.default_rng(0)
    F, Q, H, R = np.eye(3) + 0.1 * rng.standard_normal((3, 3)), 0.1 * np.eye(3), rng.standard_normal((1, 3)), np.eye(1)
    model = kalman.LinearGaussianModel(F, Q, H, R)

    def run(seed):
        z = np.random.default_rng(seed).standard_normal((50, 1))
        a = b = (np.zeros(3), np.eye(3))
        for k in range(50):
            a = kalman.update(*kalman.predict(*a, F, Q), z[k], H, R)
            b = kalman.update(*kalman.predict(*b, model), z[k], model)
        return a, b

    serial = [run(s) for s in range(16)]
    with ThreadPoolExecutor(max_workers=8) as pool:
        threaded = list(pool.map(run, range(16)))
    for (a_s, b_s), (a_t, b_t) in zip(serial, threaded):
        for u, v in ((a_s, a_t), (b_s, b_t), (a_s, b_s)):
            assert u[0].tobytes() == v[0].tobytes() and u[1].tobytes() == v[1].tobytes()


def test_model_arrays_are_read_only_copies():
    F, Q, H, R, B = np.eye(2), 0.1 * np.eye(2), np.array([[1.0, 0.0]]), np.eye(1), np.ones((2, 1))
    model = kalman.LinearGaussianModel(F, Q, H, R, B=B)
    for name in ("F", "Q", "H", "R", "B"):
        arr = getattr(model, name)
        with pytest.raises(ValueError, match="read-only"):
            arr[0, 0] = 5.0
        with pytest.raises(ValueError):
            arr.setflags(write=True)
        with pytest.raises(AttributeError, match="frozen"):
            setattr(model, name, np.eye(2))
    before = _filter_run(1, 5, model)
    F[0, 0], Q[0, 0], H[0, 0], R[0, 0], B[0, 0] = np.nan, -1.0, np.inf, 0.0, 1e300  # the caller's arrays, spoiled
    after = _filter_run(1, 5, model)
    for (x0, P0), (x1, P1) in zip(before, after):
        assert np.array_equal(x0, x1) and np.array_equal(P0, P1)


def test_model_survives_pickling():
    import pickle

    model = kalman.LinearGaussianModel(np.eye(2), 0.1 * np.eye(2), np.array([[1.0, 0.0]]), np.eye(1))
    again = pickle.loads(pickle.dumps(model))
    assert all(np.array_equal(getattr(model, k), getattr(again, k)) for k in ("F", "Q", "H", "R"))
    assert again.B is None and not again.F.flags.writeable


@pytest.mark.parametrize("arg,bad,match", [
    ("F", np.ones((2, 3)), "F must be a square"),
    ("F", np.array([[1.0, np.nan], [0.0, 1.0]]), "F contains NaN"),
    ("Q", np.eye(3), "Incompatible dimensions of Q"),
    ("Q", np.array([[1.0, 0.5], [0.0, 1.0]]), "Q must be symmetric"),
    ("Q", -np.eye(2), "Q must be positive semidefinite"),
    ("H", np.ones((1, 3)), "Incompatible dimensions of H"),
    ("H", np.array([[np.inf, 0.0]]), "H contains NaN"),
    ("R", np.zeros((1, 1)), "R must be positive definite"),
    ("R", np.eye(2), "Incompatible dimensions of R"),
    ("R", np.array([[np.nan]]), "R contains NaN"),
    ("B", np.ones((3, 1)), "Incompatible dimensions of B"),
    ("B", np.array([[1.0], [np.nan]]), "B contains NaN"),
])
def test_model_refuses_bad_matrices_by_name(arg, bad, match):
    good = dict(F=np.eye(2), Q=0.1 * np.eye(2), H=np.array([[1.0, 0.0]]), R=np.eye(1), B=np.ones((2, 1)))
    with pytest.raises(ValueError, match=match):
        kalman.LinearGaussianModel(**(good | {arg: bad}))
    with pytest.raises(TypeError, match=rf"\b{arg} must be an array"):
        kalman.LinearGaussianModel(**(good | {arg: "matrix"}))


def test_model_steps_check_the_shapes_of_each_call():
    model = kalman.LinearGaussianModel(np.eye(2), 0.1 * np.eye(2), np.array([[1.0, 0.0]]), np.eye(1), B=np.ones((2, 1)))
    x, P = np.zeros(2), np.eye(2)
    for call, match in ((lambda: kalman.predict(np.zeros(3), P, model), "dimensions of x"),
                        (lambda: kalman.predict(x, np.eye(3), model), "dimensions of P"),
                        (lambda: kalman.predict(x, P, model, np.ones(2)), "dimensions of u"),
                        (lambda: kalman.update(x, P, np.ones(2), model), "dimensions of z"),
                        (lambda: kalman.update(x, P, 1.0, model), "dimensions of z"),
                        (lambda: kalman.update(x, P, np.ones(1), model, np.eye(1)), "H and R are the model's"),
                        (lambda: kalman.predict(x, P, model, np.eye(2), u=np.ones(1)), "F, Q and B are the model's"),
                        (lambda: model.check_state(x, -np.eye(2)), "P must be positive semidefinite"),
                        (lambda: model.check_state(np.zeros(3), np.eye(3)), "dimensions of x")):
        with pytest.raises((ValueError, TypeError), match=match):
            call()


def test_model_forms_equal_the_plain_forms_with_inputs_and_batches():
    """predict/update/run_filter on a model give the plain-array forms' numbers, bit for bit, batched too."""
    rng = np.random.default_rng(8)
    model_ = agents.double_integrator(2, 0.1)
    H, Q, R = np.eye(2, 4), 0.05 * np.eye(4), 0.3 * np.eye(2)
    model = kalman.LinearGaussianModel(model_.A, Q, H, R, B=model_.B)
    X, P = rng.standard_normal((5, 4)), np.stack([_random_spd(rng, 4) for _ in range(5)])
    U, Z = rng.standard_normal((5, 2)), rng.standard_normal((5, 2))
    a = kalman.update(*kalman.predict(X, P, model_.A, Q, B=model_.B, u=U), Z, H, R)
    b = kalman.update(*kalman.predict(X, P, model, u=U), Z, model)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    z = rng.standard_normal((20, 5, 2))
    plain = kalman.run_filter(X, P, z, model_.A, Q, H, R)
    checked = kalman.run_filter(X, P, z, kalman.LinearGaussianModel(model_.A, Q, H, R))
    assert np.array_equal(plain[0], checked[0]) and np.array_equal(plain[1], checked[1])


def test_with_measurement_is_the_constructor_and_checks_only_the_measurement():
    model = kalman.LinearGaussianModel(F=[[1.0, 0.1], [0.0, 1.0]], Q=0.01 * np.eye(2), H=[[1.0, 0.0]], R=[[0.5]])
    other = model.with_measurement([[0.0, 1.0], [1.0, 1.0]], np.diag([2.0, 3.0]))
    assert other == kalman.LinearGaussianModel([[1.0, 0.1], [0.0, 1.0]], 0.01 * np.eye(2), [[0.0, 1.0], [1.0, 1.0]],
                                               np.diag([2.0, 3.0]))
    assert other.F is model.F and other.Q is model.Q                    # the checked dynamics, shared
    x, P = kalman.update(np.zeros(2), np.eye(2), [1.0, 2.0], other)
    np.testing.assert_array_equal(x, kalman.update(np.zeros(2), np.eye(2), [1.0, 2.0], [[0.0, 1.0], [1.0, 1.0]],
                                                   np.diag([2.0, 3.0]))[0])
    with pytest.raises(ValueError, match=r"R must be positive definite"):
        model.with_measurement([[1.0, 0.0]], [[-1.0]])
    with pytest.raises(ValueError, match=r"Incompatible dimensions of H"):
        model.with_measurement([[1.0, 0.0, 0.0]], [[1.0]])


def test_predict_refuses_estimates_and_covariances_of_two_batches():
    model = kalman.LinearGaussianModel(np.eye(2), 0.1 * np.eye(2), [[1.0, 0.0]], [[1.0]])
    P = np.eye(2) * np.arange(1.0, 5.0)[:, None, None]  # 4 covariances for 3 estimates
    for call in (lambda: model.predict(np.zeros((3, 2)), P), lambda: kalman.predict(np.zeros((3, 2)), P, np.eye(2),
                                                                                      0.1 * np.eye(2))):
        with pytest.raises(ValueError, match="batch axes of x \\(3, 2\\), P \\(4, 2, 2\\)"):
            call()
