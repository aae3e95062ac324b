"""Tests of mascore.set_membership: SDPs (eqs. (6)-(8)) vs closed-form twins, guarantees, errors."""

import numpy as np
import pytest

from mascore import _solver
from mascore import ellipsoids as el
from mascore import set_membership as smf
from mascore._solver import SolverError

# Bhattacharjee and Subbarao (2021), eq. (23) and the SMF parameters of Sec. 5
A = np.array([[0.0, -1.0], [1.0, 0.0]])
C = np.array([[1.0, 0.0]])
D = np.eye(1)
G = np.eye(2)
Q = 0.1 * np.eye(2)
R = 0.1 * np.eye(1)


def random_spd(rng, n, floor=0.05):
    M = rng.standard_normal((n, n))
    return M @ M.T + floor * np.eye(n)


def random_case(seed, p=2):
    rng = np.random.default_rng(seed)
    n, nv, nw = 3, p, 2
    return dict(
        c=rng.standard_normal(n), P=random_spd(rng, n), A=rng.standard_normal((n, n)),
        G=rng.standard_normal((n, nw)), Q=random_spd(rng, nw, 0.2), C=rng.standard_normal((p, n)),
        D=rng.standard_normal((p, nv)) + 2 * np.eye(p, nv), R=random_spd(rng, nv, 0.2), rng=rng,
    )


def test_paper_example_first_correction_sdp_equals_closed_form():
    """Sec. 5 at k = 0: prior E([50, -50], 2 I), R = 0.1: both methods give the same trace, gain and centre."""
    c, P, y = np.array([50.0, -50.0]), 2 * np.eye(2), np.array([50.6])
    out = {m: smf.correct(c, P, y, C, D, R, method=m) for m in smf.SOLVERS}
    (cs, Ps, Ls), (cf, Pf, Lf) = out["sdp"], out["closed_form"]
    assert np.trace(Ps) == pytest.approx(np.trace(Pf), rel=1e-6)
    assert np.allclose(Ls, Lf, atol=1e-4) and np.allclose(cs, cf, atol=1e-4)
    assert np.trace(Pf) < np.trace(P)  # the correction shrinks the trace from 4


def test_paper_example_prediction_sdp_equals_closed_form():
    c, P = np.array([1.0, 2.0]), np.diag([0.5, 1.8])
    cs, Ps = smf.predict(c, P, A, G, Q, method="sdp")
    cf, Pf = smf.predict(c, P, A, G, Q, method="closed_form")
    assert np.trace(Ps) == pytest.approx(np.trace(Pf), rel=1e-6)
    assert np.allclose(cs, A @ c) and np.allclose(cf, A @ c)
    # closed form of the trace-optimal Minkowski sum
    assert np.trace(Pf) == pytest.approx((np.sqrt(np.trace(A @ P @ A.T)) + np.sqrt(np.trace(Q))) ** 2)


@pytest.mark.parametrize("p", [1, 2])  # p = 1: the analytic t*; p = 2: the Newton search
@pytest.mark.parametrize("seed", range(4))
def test_random_cases_sdp_equals_closed_form(seed, p):
    k = random_case(seed, p)
    y = k["C"] @ k["c"] + 0.1
    _, Ps, _ = smf.correct(k["c"], k["P"], y, k["C"], k["D"], k["R"], method="sdp")
    _, Pf, _ = smf.correct(k["c"], k["P"], y, k["C"], k["D"], k["R"], method="closed_form")
    assert np.trace(Ps) == pytest.approx(np.trace(Pf), rel=1e-6)
    _, Ps = smf.predict(k["c"], k["P"], k["A"], k["G"], k["Q"], method="sdp")
    _, Pf = smf.predict(k["c"], k["P"], k["A"], k["G"], k["Q"], method="closed_form")
    assert np.trace(Ps) == pytest.approx(np.trace(Pf), rel=1e-6)


@pytest.mark.parametrize("method", smf.SOLVERS)
def test_correction_contains_every_consistent_state(method):
    """Points of the prior whose output is consistent with y (the true set) lie in E(x_{k|k}, P_{k|k})."""
    k = random_case(11)
    rng = k["rng"]
    x_true = k["c"] + el.sample_interior(rng, np.zeros(3), k["P"], 1)[0]
    v = el.sample_boundary(rng, np.zeros(2), k["R"], 1)[0]
    y = k["C"] @ x_true + k["D"] @ v
    c, P, _ = smf.correct(k["c"], k["P"], y, k["C"], k["D"], k["R"], method=method)
    cands = np.concatenate([el.sample_interior(rng, k["c"], k["P"], 30_000), el.sample_boundary(rng, k["c"], k["P"], 10_000)])
    W = k["D"] @ k["R"] @ k["D"].T
    r = y - cands @ k["C"].T
    true_set = cands[np.einsum("ij,ij->i", r, np.linalg.solve(W, r.T).T) <= 1.0]
    assert true_set.shape[0] > 50
    assert np.all(el.contains(np.vstack([true_set, x_true]), c, P, rtol=1e-6))


@pytest.mark.parametrize("method", smf.SOLVERS)
def test_prediction_contains_true_successor_set(method):
    k = random_case(12)
    rng = k["rng"]
    B, u = np.eye(3)[:, :1], np.array([0.7])
    c, P = smf.predict(k["c"], k["P"], k["A"], k["G"], k["Q"], B=B, u=u, method=method)
    x = el.sample_boundary(rng, k["c"], k["P"], 3000)
    w = el.sample_boundary(rng, np.zeros(2), k["Q"], 3000)
    succ = x @ k["A"].T + u @ B.T + w @ k["G"].T
    assert np.all(el.contains(succ, c, P, rtol=1e-6))


def test_run_filter_keeps_true_state_inside_and_shrinks():
    """Algorithm 1 in open loop on the paper's agent model, bounded uniform noise, closed-form path."""
    rng = np.random.default_rng(3)
    T, n_sys = 80, 50
    x = np.array([50.0, -50.0]) + rng.random((n_sys, 2))
    ys, xs = [], []
    for _ in range(T + 1):
        ys.append(x @ C.T + rng.uniform(-0.05, 0.05, (n_sys, 1)))
        xs.append(x)
        x = x @ A.T + rng.uniform(-0.05, 0.05, (n_sys, 2))
    hist = smf.run_filter(np.tile([50.0, -50.0], (n_sys, 1)), 2 * np.eye(2), np.array(ys), A, G, C, D, Q, R)
    xs = np.array(xs)
    assert np.all(el.mahalanobis_sq(xs, hist.center_corr, hist.shape_corr) <= 1 + 1e-9)
    tr = np.trace(hist.shape_corr, axis1=-2, axis2=-1)
    assert np.all(tr[-1] < 4.0) and np.allclose(tr[-1], tr[-1, 0])


def test_run_filter_sdp_matches_closed_form_over_a_few_steps():
    """Chained over steps the paths agree to O(sqrt(solver tol)): the trace is flat at its optimum,
    so a tiny trace gap still moves the shape (and hence the next step) by ~1e-5."""
    rng = np.random.default_rng(8)
    ys = rng.uniform(-0.2, 0.2, (4, 1))
    kw = dict(x0_hat=np.zeros(2), P0=2 * np.eye(2), y=ys, A=A, G=G, C=C, D=D, Q=Q, R=R)
    hs, hf = smf.run_filter(**kw, method="sdp"), smf.run_filter(**kw, method="closed_form")
    assert np.allclose(np.trace(hs.shape_corr, axis1=1, axis2=2), np.trace(hf.shape_corr, axis1=1, axis2=2), rtol=1e-4)


def test_batched_closed_form_equals_loop():
    rng = np.random.default_rng(4)
    cs = rng.standard_normal((3, 4, 2))
    Ps = np.stack([[random_spd(rng, 2) for _ in range(4)] for _ in range(3)])
    ys = rng.standard_normal((3, 4, 1)) * 0.1 + cs[..., :1]
    cb, Pb, Lb = smf.correct(cs, Ps, ys, C, D, R, check_consistency=False)
    for i in range(3):
        for j in range(4):
            c1, P1, L1 = smf.correct(cs[i, j], Ps[i, j], ys[i, j], C, D, R, check_consistency=False)
            assert np.allclose(cb[i, j], c1) and np.allclose(Pb[i, j], P1) and np.allclose(Lb[i, j], L1)


# ------------------------------------------------------------------ bad input


@pytest.mark.parametrize("method", smf.SOLVERS)
def test_empty_intersection_names_step_and_agent(method):
    c, P = np.zeros((4, 2)), np.broadcast_to(np.eye(2), (4, 2, 2))
    y = np.zeros((4, 1))
    y[2] = 5.0  # |y - C c| = 5 > sqrt(0.1) + 1: the strip misses agent 3's ellipsoid
    with pytest.raises(ValueError, match=r"correction step, k = 7, agent 3.*empty intersection.*a bound is too small"):
        smf.correct(c, P, y, C, D, R, method=method, step=7, agent=np.arange(1, 5))


@pytest.mark.parametrize("method", smf.SOLVERS)
def test_non_pd_shape_names_step_and_agent(method):
    P = np.stack([np.eye(2), np.diag([1.0, -0.1])])
    with pytest.raises(ValueError, match=r"prediction step, k = 4, agent 2.*not symmetric positive definite"):
        smf.predict(np.zeros((2, 2)), P, A, G, Q, method=method, step=4, agent=[1, 2])
    with pytest.raises(ValueError, match=r"correction step, k = 0, agent 5.*positive definite"):
        smf.correct(np.zeros(2), np.diag([1.0, 0.0]), [0.0], C, D, R, method=method, step=0, agent=5)


@pytest.mark.filterwarnings("ignore:Solution may be inaccurate")
def test_solver_not_optimal_raises_solver_error(monkeypatch):
    monkeypatch.setitem(_solver.SOLVER_OPTIONS, "max_iter", 1)
    with pytest.raises(SolverError, match=r"correction SDP eq. \(6\), k = 2, agent 1"):
        smf.correct(np.zeros(2), 2 * np.eye(2), [0.1], C, D, R, method="sdp", step=2, agent=1)
    with pytest.raises(SolverError, match=r"prediction SDP eq. \(8\), k = 2, agent 1"):
        smf.predict(np.zeros(2), 2 * np.eye(2), A, G, Q, method="sdp", step=2, agent=1)


def test_bad_arguments():
    with pytest.raises(ValueError, match="method must be one of"):
        smf.correct(np.zeros(2), np.eye(2), [0.0], C, D, R, method="ellipsoid")
    with pytest.raises(ValueError, match="R must be symmetric positive definite"):
        smf.correct(np.zeros(2), np.eye(2), [0.0], C, D, -R)
    with pytest.raises(ValueError, match="Incompatible dimensions of C"):
        smf.correct(np.zeros(2), np.eye(2), [0.0], np.ones((1, 3)), D, R)
    with pytest.raises(ValueError, match="give both B and u"):
        smf.predict(np.zeros(2), np.eye(2), A, G, Q, B=np.eye(2))
    with pytest.raises(ValueError, match=r"correction step, k = 3, agent 2: y has NaN"):
        smf.correct(np.zeros(2), np.eye(2), [np.nan], C, D, R, step=3, agent=2)
    with pytest.raises(ValueError, match="u must be finite with last dimension 2"):
        smf.predict(np.zeros(2), np.eye(2), A, G, Q, B=np.eye(2), u=[0.0, np.inf])
    with pytest.raises(ValueError, match="u must be finite with last dimension 2"):
        smf.predict(np.zeros(2), np.eye(2), A, G, Q, B=np.eye(2), u=[0.0])


def test_cached_system_matrices_do_not_alias_the_callers_arrays():
    """System matrices are validated once per value; changing the caller's array afterwards changes the result."""
    Qm = Q.copy()
    _, P1 = smf.predict(np.zeros(2), np.eye(2), A, G, Qm)
    Qm *= 4.0  # same object, new value: must not hit the old cache entry
    _, P2 = smf.predict(np.zeros(2), np.eye(2), A, G, Qm)
    assert np.trace(P2) == pytest.approx((np.sqrt(np.trace(A @ A.T)) + np.sqrt(np.trace(Qm))) ** 2)
    assert np.trace(P2) > np.trace(P1)
    with pytest.raises(ValueError, match="Q must be symmetric positive definite"):
        smf.predict(np.zeros(2), np.eye(2), A, G, -Qm)


def test_solver_options_reach_the_solver_and_a_starved_solver_says_how_to_fix_it():
    """solver_options is passed to Clarabel: one iteration cannot solve the SDP, and the error says what to change."""
    from mascore import SolverError

    args = (np.zeros(2), np.eye(2), np.array([0.1]), [[1.0, 0.0]], [[1.0]], [[1.0]])
    c1, P1, _ = smf.correct(*args, method="sdp")
    c2, P2, _ = smf.correct(*args, method="sdp", solver_options={"max_iter": 200, "tol_gap_rel": 1e-10})
    np.testing.assert_allclose(P2, P1, atol=1e-6)
    with pytest.raises(SolverError, match="correction SDP"):
        smf.correct(*args, method="sdp", solver_options={"max_iter": 1})
    with pytest.raises(TypeError, match="solver_options"):
        smf.correct(*args, method="sdp", solver_options=["max_iter", 1])


# --------------------------------------------------------------------------- checked model


def _model(**kw):
    args = dict(A=[[1.0, 0.1], [0.0, 1.0]], G=np.eye(2), C=[[1.0, 0.0]], D=[[1.0]], Q=1e-3 * np.eye(2), R=[[0.04]])
    args.update(kw)
    return smf.SetMembershipModel(**args)


def _run_model(seed, method, n_steps=4):
    """An independent filter: its own model (and compiled SDPs), a few steps, every output."""
    rng = np.random.default_rng(seed)
    model = _model()
    c, P = np.zeros(2), np.eye(2)
    out = []
    for k in range(n_steps):
        c, P, L = model.correct(c, P, rng.uniform(-0.1, 0.1, 1), method=method, step=k)
        c, P = model.predict(c, P, method=method, step=k)
        out += [c, P, L]
    return out


@pytest.mark.parametrize("method", smf.SOLVERS)
def test_eight_threads_give_the_serial_results_byte_for_byte(method):
    """No module-level state: 8 threads, one model each, reproduce a serial run exactly (both methods)."""
    from concurrent.futures import ThreadPoolExecutor

    seeds = list(range(8))
    serial = [_run_model(s, method) for s in seeds]
    with ThreadPoolExecutor(max_workers=8) as pool:
        threaded = list(pool.map(lambda s: _run_model(s, method), seeds))
    for a, b in zip(serial, threaded):
        for x, y in zip(a, b):
            assert x.shape == y.shape and x.tobytes() == y.tobytes()


@pytest.mark.parametrize("method", smf.SOLVERS)
def test_model_methods_equal_the_plain_functions(method):
    A_, G_, C_, D_, Q_, R_ = [[1.0, 0.1], [0.0, 1.0]], np.eye(2), [[1.0, 0.0]], [[1.0]], 1e-3 * np.eye(2), [[0.04]]
    model = _model()
    got = model.correct(np.zeros(2), np.eye(2), [0.05], method=method)
    want = smf.correct(np.zeros(2), np.eye(2), [0.05], C_, D_, R_, method=method)
    for a, b in zip(got, want):
        np.testing.assert_array_equal(a, b)
    got = model.predict(got[0], got[1], method=method)
    want = smf.predict(want[0], want[1], A_, G_, Q_, method=method)
    for a, b in zip(got, want):
        np.testing.assert_array_equal(a, b)
    y = np.array([[0.05], [0.0], [-0.02]])
    h1 = model.run(np.zeros(2), np.eye(2), y, method=method)
    h2 = smf.run_filter(np.zeros(2), np.eye(2), y, A_, G_, C_, D_, Q_, R_, method=method)
    for f in ("center_corr", "shape_corr", "center_pred", "shape_pred", "gain"):
        np.testing.assert_array_equal(getattr(h1, f), getattr(h2, f))


def test_model_arrays_are_read_only_copies():
    A_ = np.array([[1.0, 0.1], [0.0, 1.0]])
    R_ = np.array([[0.04]])
    model = _model(A=A_, R=R_)
    ref = _model()
    A_[0, 0] = 50.0  # the caller's arrays, changed after the check, cannot reach the model
    R_[0, 0] = -1.0
    for name in ("A", "G", "C", "D", "Q", "R", "W", "GQG"):
        arr = getattr(model, name)
        assert not arr.flags.writeable
        with pytest.raises(ValueError, match="read-only"):
            arr[0, 0] = 1.0
    with pytest.raises(AttributeError):
        model.A = np.eye(2)
    a = model.predict(*model.correct(np.zeros(2), np.eye(2), [0.05])[:2])
    b = ref.predict(*ref.correct(np.zeros(2), np.eye(2), [0.05])[:2])
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(R=[[-1.0]]), ValueError, "R must be symmetric positive definite"),
    (dict(Q=-np.eye(2)), ValueError, "Q must be symmetric positive definite"),
    (dict(C=[[1.0, 0.0, 0.0]]), ValueError, "Incompatible dimensions of C"),
    (dict(A=np.eye(3)), ValueError, "G"),
    (dict(A="A"), TypeError, "A"),
    (dict(D=[[np.nan]]), ValueError, "D"),
    (dict(Q=None), ValueError, "A, G and Q together"),
    (dict(B=np.eye(3)), ValueError, "B"),
])
def test_bad_model_arguments_are_refused_by_name(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        _model(**kwargs)


def test_model_checks_each_call_and_its_parts():
    model = _model(B=np.eye(2))
    with pytest.raises(ValueError, match="give both B and u"):
        model.predict(np.zeros(2), np.eye(2))
    with pytest.raises(ValueError, match="center has size 3"):
        model.correct(np.zeros(3), np.eye(3), [0.0])
    with pytest.raises(ValueError, match="shape matrix is not symmetric positive definite"):
        model.correct(np.zeros(2), -np.eye(2), [0.0])
    measurement_only = smf.SetMembershipModel(C=[[1.0, 0.0]], D=[[1.0]], R=[[0.04]])
    assert measurement_only.n == 2
    with pytest.raises(ValueError, match="no A, G, Q"):
        measurement_only.predict(np.zeros(2), np.eye(2))
