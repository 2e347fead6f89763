"""Error-state model against the non-linear strapdown mechanisation.

The key test perturbs every state of the error vector on a moving, turning, accelerating
trajectory, runs the non-linear mechanisation (nav/strapdown.py) perturbed and unperturbed for
10 s, and compares the real error with Φ δx0 from the linear model.  The unperturbed run of the
same ideal increments is the truth, so the mechanisation's own algorithm error cancels.
"""

import numpy as np
import pytest

from ins_gnss_ros.nav import discretize as dz
from ins_gnss_ros.nav import error_model as em
from ins_gnss_ros.nav import sensor_errors as se
from ins_gnss_ros.nav.earth import WGS84, radii
from ins_gnss_ros.nav.rotations import quat_from_rotvec, quat_mul
from ins_gnss_ros.nav.strapdown import NavState, apply_correction, run
from ins_gnss_ros.sim.trajectory import Kinematics, generate

DEG = np.pi / 180.0


class Manoeuvre:
    """Accelerating, turning, climbing and rolling motion (analytic kinematics)."""

    def evaluate(self, t):
        speed, dspeed = 12.0 + 1.5 * t, 1.5 + 0 * t
        course = 0.4 + 0.25 * t + 0.3 * np.sin(0.5 * t)
        dcourse = 0.25 + 0.15 * np.cos(0.5 * t)
        vu, dvu = 0.8 * np.sin(0.6 * t), 0.48 * np.cos(0.6 * t)
        c, s = np.cos(course), np.sin(course)
        v = np.stack([speed * c, speed * s, vu], -1)
        a = np.stack([dspeed * c - speed * s * dcourse, dspeed * s + speed * c * dcourse, dvu], -1)
        roll, droll = 0.1 * np.sin(0.9 * t), 0.09 * np.cos(0.9 * t)
        pitch, dpitch = -0.05 * np.sin(0.6 * t), -0.03 * np.cos(0.6 * t)
        return Kinematics(v, a, np.stack([roll, pitch, course], -1),
                          np.stack([droll, dpitch, dcourse], -1))


def reference(duration=10.0, rate=100.0, lat=50.0 * DEG):
    traj = generate(Manoeuvre(), lat, 10.0 * DEG, 300.0, duration, rate=rate, oversample=2)
    state0 = NavState(traj.lat[0], traj.lon[0], traj.h[0], traj.v_enu[0], traj.q_nb[0])
    return traj, state0


def states_of(out):
    return [NavState(out["lat"][k], out["lon"][k], out["h"][k], out["v_enu"][k],
                     out["q_nb"][k], out["t"][k]) for k in range(len(out["t"]))]


def inject(state, dp, dv, phi, ell=WGS84):
    """Exact inverse of em.nav_error: the state whose error w.r.t. ``state`` is (dp, dv, phi)."""
    rm, rn = radii(state.lat, ell)
    return NavState(state.lat + dp[1] / (rm + state.h),
                    state.lon + dp[0] / ((rn + state.h) * np.cos(state.lat)),
                    state.h + dp[2], state.v_enu + dv,
                    quat_mul(quat_from_rotvec(-np.asarray(phi)), state.q_nb), state.t)


def linear_phi(layout, states, f_b, w_b, dt):
    """Φ over the run: product of per-step exp(F̄ dt), F̄ the mean of the step's end values."""
    phi = np.eye(layout.size)
    F_prev = em.system_matrix(layout, states[0], f_b[0], w_b[0])
    for k in range(len(f_b)):
        F_next = em.system_matrix(layout, states[k + 1], f_b[k], w_b[k])
        phi = dz.picard_transition(0.5 * (F_prev + F_next), dt, 4) @ phi
        F_prev = F_next
    return phi


LAYOUT = em.StateLayout(("pos", "vel", "att", "bg", "ba", "gmg", "gma", "sg", "sa", "ng",
                         "na", "nz", "gs"), {"gmg": 20.0, "gma": 30.0})
#: Perturbation size per block: small enough to stay linear (2 km is 3e-4 of the Earth's
#: radius), large enough that the small curvature and transport-rate terms show.
SIZE = {"pos": 2000.0, "vel": 0.1, "att": 1e-3, "bg": 2e-5, "ba": 2e-3, "gmg": 2e-5,
        "gma": 2e-3, "sg": 1e-3, "sa": 1e-3, "ng": 1e-3, "na": 1e-3, "nz": 1e-3, "gs": 2e-6}
#: Absolute floors (far below every real error, above double-precision noise).
FLOOR = {"pos": 1e-6, "vel": 1e-8, "att": 1e-10}


@pytest.fixture(scope="module")
def nonlinear_vs_linear():
    dt = 0.01
    traj, state0 = reference(10.0, 1.0 / dt)
    dth, dvs = traj.dtheta, traj.dv
    ref = run(state0, dth, dvs, dt)
    ref_states = states_of(ref)
    # Rates and specific force of each interval for F (the model's inputs).
    w_b, f_b = dth / dt, dvs / dt
    phi = linear_phi(LAYOUT, ref_states, f_b, w_b, dt)
    t_mid = (np.arange(len(dth)) + 0.5) * dt
    S = LAYOUT.slices
    results = []
    for name in LAYOUT.blocks:
        for i in range(S[name].stop - S[name].start):
            x0 = np.zeros(LAYOUT.size)
            x0[S[name].start + i] = SIZE[name] * (1 if i % 2 == 0 else -1)
            st0 = inject(state0, x0[S["pos"]], x0[S["vel"]], x0[S["att"]])
            Mg = se.error_matrix(x0[S["sg"]], x0[S["ng"]])
            Ma = se.error_matrix(x0[S["sa"]], x0[S["na"]])
            Ma[2, :2] += x0[S["nz"]]  # the z accelerometer reading x and y
            Gs = x0[S["gs"]].reshape(3, 3)
            bg = x0[S["bg"]] + np.outer(np.exp(-t_mid / LAYOUT.tau["gmg"]), x0[S["gmg"]])
            ba = x0[S["ba"]] + np.outer(np.exp(-t_mid / LAYOUT.tau["gma"]), x0[S["gma"]])
            dth_m = dth + dth @ Mg.T + dvs @ Gs.T + bg * dt
            dv_m = dvs + dvs @ Ma.T + ba * dt
            out = run(st0, dth_m, dv_m, dt)
            end = states_of({k: v[-1:] for k, v in out.items()})[0]
            # Compare the error growth: the perturbation itself would hide small terms.
            real = np.concatenate(em.nav_error(end, ref_states[-1])) - x0[:9]
            pred = (phi @ x0)[:9] - x0[:9]
            results.append((f"{name}[{i}]", real, pred))
    return results


def test_injection_is_inverse_of_nav_error():
    _, s0 = reference(0.1)
    x = np.array([3.0, -2.0, 1.5, 0.1, -0.2, 0.05, 1e-3, -2e-3, 3e-3])
    err = np.concatenate(em.nav_error(inject(s0, x[:3], x[3:6], x[6:]), s0))
    np.testing.assert_allclose(err, x, rtol=1e-6)


def test_nav_error_agrees_with_strapdown_correction():
    """apply_correction (strapdown.py) must remove exactly the error nav_error reports."""
    _, s0 = reference(0.1)
    est = inject(s0, [3.0, -2.0, 1.5], [0.1, -0.2, 0.05], [1e-3, -2e-3, 3e-3])
    fixed = apply_correction(est, *em.nav_error(est, s0))
    for e in em.nav_error(fixed, s0):
        assert np.abs(e).max() < 1e-5


def test_linear_model_matches_nonlinear_mechanisation(nonlinear_vs_linear):
    """Every perturbed state: error growth |real - Φδx0| <= 2 % |real - δx0| per block."""
    bad = []
    for label, real, pred in nonlinear_vs_linear:
        for blk, sl in (("pos", slice(0, 3)), ("vel", slice(3, 6)), ("att", slice(6, 9))):
            r, p = real[sl], pred[sl]
            if np.linalg.norm(r - p) > 0.02 * np.linalg.norm(r) + FLOOR[blk]:
                bad.append((label, blk, r, p))
    assert not bad, "\n".join(f"{l} {b}: real {r} pred {p}" for l, b, r, p in bad)


def test_every_perturbation_produces_a_visible_error(nonlinear_vs_linear):
    """Guards the key test against vacuous passes (an error below the floors)."""
    for label, real, _ in nonlinear_vs_linear:
        assert np.linalg.norm(real[:3]) > 1e-3 or label.startswith("pos"), label


def test_layout_presets_and_slices():
    assert em.make_layout("15").size == 15
    assert em.make_layout("21").size == 21
    L24 = em.make_layout("24")
    assert L24.size == 24 and L24["clock"] == slice(21, 24)
    assert em.make_layout("33").size == 33
    L17 = em.make_layout("17")
    assert L17.size == 17 and L17["nz"] == slice(15, 17)
    L = em.make_layout(["pos", "vel", "att", "gs"])
    assert L["gs"] == slice(9, 18) and "bg" not in L
    with pytest.raises(ValueError):
        em.make_layout(["vel", "pos", "att"])
    with pytest.raises(ValueError):
        em.make_layout(["pos", "vel", "att", "bogus"])


def test_gauss_markov_tau_comes_from_noise():
    noise = se.filter_noise(se.TACTICAL, "gm")
    L = em.make_layout("21gm", noise)
    assert L.tau == {"gmg": 300.0, "gma": 300.0}
    F = em.system_matrix(L, reference(0.1)[1], [0, 0, 9.8], [0, 0, 0])
    np.testing.assert_allclose(np.diag(F[L["gmg"], L["gmg"]]), -1 / 300.0)


def test_clock_block_is_triple_integrator():
    L = em.make_layout("24")
    F = em.system_matrix(L, reference(0.1)[1], [0, 0, 9.8], [0, 0, 0])
    t = 3.0
    phi = dz.van_loan(F, np.zeros_like(F), t)[0][L["clock"], L["clock"]]
    np.testing.assert_allclose(phi, [[1, t, t * t / 2], [0, 1, t], [0, 0, 1]], atol=1e-12)


def test_vertical_channel_instability_rate():
    """Free height error grows like cosh(t √(2g/R)): F[δv_U, δp_U] = 2g/R."""
    L = em.make_layout("9")
    s = NavState(0.7, 0.2, 0.0)
    F = em.system_matrix(L, s, [0, 0, 9.8], [0, 0, 0])
    lam2 = F[5, 2]
    g = 9.80665
    assert lam2 == pytest.approx(2 * g / 6.371e6, rel=0.01)


def test_noise_input_structure():
    """Q = G Qc G^T: isotropic white noise is attitude-independent (Babich eq. 6.9)."""
    noise = se.filter_noise(se.MEMS_ADIS16405, "rw")
    L = em.make_layout("21")
    Q = []
    for rv in ([0, 0, 0], [0.3, -1.0, 2.0]):
        s = NavState(0.7, 0.2, 0.0, q_nb=quat_from_rotvec(rv))
        G, Qc = em.noise_input(L, s, noise)
        Q.append(G @ Qc @ G.T)
    np.testing.assert_allclose(Q[0], Q[1], atol=1e-20)
    d = np.diag(Q[0])
    np.testing.assert_allclose(d[6:9], noise.gyro_psd)
    np.testing.assert_allclose(d[3:6], noise.accel_psd)
    np.testing.assert_allclose(d[9:12], noise.blocks["bg"].psd)
    assert np.all(d[0:3] == 0) and np.all(d[15:21] == 0)
    P0 = em.initial_covariance(L, noise, 2.0, 0.1, 1e-3)
    np.testing.assert_allclose(np.sqrt(np.diag(P0))[15:18], se.MEMS_ADIS16405.gyro.scale_sigma)
