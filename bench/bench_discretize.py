"""Picard series vs Van Loan: accuracy, definiteness and cost of Φ_k and Q_k.

Run:  .venv/bin/python bench/bench_discretize.py
Prints markdown tables (copied into docs/results/error_model.md).

Cases: "seed" is Babich's 33-state reference (seed 001 extract B3: lat 55.75°, V = (150, 100, 5)
m/s, f_b = (0.5, 1.0, 9.9) m/s², ω = (0.05, -0.02, 0.1) rad/s, ARW 0.1 °/√h, VRW 0.05 m/s/√h,
10 °/h, 1 mg, T = 3600 s, σ = 1e-4); "mems21" is the project's 21-state model with the
ADIS16405-like preset on a car (lat 45°, 15 m/s, turning at 0.3 rad/s).
"""

import os

# Small matrices: BLAS threads only add contention on a shared machine.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import timeit  # noqa: E402
import types  # noqa: E402

import numpy as np  # noqa: E402
from scipy.linalg import expm  # noqa: E402

from ins_gnss_ros.nav import discretize as dz  # noqa: E402
from ins_gnss_ros.nav import error_model as em  # noqa: E402
from ins_gnss_ros.nav import sensor_errors as se  # noqa: E402
from ins_gnss_ros.nav.rotations import quat_from_euler  # noqa: E402

DEG = np.pi / 180.0
HOUR = 3600.0


def case(name):
    if name == "seed":
        noise = se.FilterNoise(8.46e-10, 6.94e-7, {
            "bg": se.BlockNoise(10 * se.DEG_PER_HOUR, psd=2 * (10 * se.DEG_PER_HOUR) ** 2 / HOUR),
            "ba": se.BlockNoise(se.MILLI_G, psd=2 * se.MILLI_G ** 2 / HOUR),
            **{k: se.BlockNoise(1e-4, HOUR, 2e-8 / HOUR) for k in ("sg", "sa", "ng", "na")}})
        layout = em.make_layout("33", noise)
        st = types.SimpleNamespace(lat=55.75 * DEG, h=200.0, v_enu=np.array([150.0, 100.0, 5.0]),
                                   q_nb=quat_from_euler(0.1, -0.2, 0.7))
        f, w = [0.5, 1.0, 9.9], [0.05, -0.02, 0.1]
    else:
        noise = se.filter_noise(se.MEMS_ADIS16405, "rw")
        layout = em.make_layout("21", noise)
        st = types.SimpleNamespace(lat=45 * DEG, h=100.0, v_enu=np.array([15.0, 8.0, 0.3]),
                                   q_nb=quat_from_euler(0.05, 0.03, 1.0))
        f, w = [1.2, -0.8, 9.85], [0.01, -0.02, 0.3]
    F = em.system_matrix(layout, st, f, w)
    G, Qc = em.noise_input(layout, st, noise)
    return F, G @ Qc @ G.T


def accuracy_table(name):
    F, Q = case(name)
    print(f"\n### Case {name}: n = {F.shape[0]}, ||F||_2 = {np.linalg.norm(F, 2):.3g} 1/s\n")
    print("| Δt [s] | ν | rel. err Φ (max abs) | rel. err Q_k (Frobenius) | rel. err pos. block "
          "| min eig Q_k | PSD margin |")
    print("|---|---|---|---|---|---|---|")
    for dt in (0.01, 0.1, 1.0):
        phi_ref, Q_ref = dz.van_loan(F, Q, dt)
        for nu in range(1, 7):
            phi = dz.picard_transition(F, dt, nu)
            Qk = dz.picard_process_noise(F, Q, dt, nu)
            e_phi = np.abs(phi - phi_ref).max()
            e_q = np.linalg.norm(Qk - Q_ref) / np.linalg.norm(Q_ref)
            e_p = np.linalg.norm(Qk[:3, :3] - Q_ref[:3, :3]) / np.linalg.norm(Q_ref[:3, :3])
            print(f"| {dt} | {nu} | {e_phi:.1e} | {e_q:.1e} | {e_p:.1e} | "
                  f"{np.linalg.eigvalsh(Qk)[0]:.2e} | {dz.psd_margin(Qk):.2e} |")
        Qb = dz.book_process_noise(F, Q, dt)
        print(f"| {dt} | book (3.1) | – | {np.linalg.norm(Qb - Q_ref) / np.linalg.norm(Q_ref):.1e}"
              f" | {np.linalg.norm(Qb[:3, :3] - Q_ref[:3, :3]) / np.linalg.norm(Q_ref[:3, :3]):.1e}"
              f" | {np.linalg.eigvalsh(Qb)[0]:.2e} | {dz.psd_margin(Qb):.2e} |")


def slope_table(name):
    F, Q = case(name)
    dts = 0.2 / 2.0 ** np.arange(5)
    print(f"\nLog-log slope of rel. err Q_k vs Δt ({name}, Δt = 0.0125…0.2 s; theory ν):")
    for nu in range(1, 6):
        err = [np.linalg.norm(dz.picard_process_noise(F, Q, dt, nu) - dz.van_loan(F, Q, dt)[1])
               / np.linalg.norm(dz.van_loan(F, Q, dt)[1]) for dt in dts]
        print(f"  ν = {nu}: slope {np.polyfit(np.log(dts), np.log(err), 1)[0]:.3f}")


def timing(name):
    F, Q = case(name)
    P = np.eye(F.shape[0])
    dt = 0.01
    print(f"\nCost per step, case {name} (n = {F.shape[0]}), best of 5 × 200 calls:")
    rows = [("Picard Q_k ν=3", lambda: dz.picard_process_noise(F, Q, dt, 3)),
            ("Picard Φ+Q_k ν=3", lambda: (dz.picard_transition(F, dt, 3),
                                           dz.picard_process_noise(F, Q, dt, 3))),
            ("Picard P⁻ (eq. 4.5) ν=3", lambda: dz.picard_predict(P, F, Q, dt, 3)),
            ("Picard P⁻ (eq. 4.5) ν=5", lambda: dz.picard_predict(P, F, Q, dt, 5)),
            ("book Q_k (3.1)", lambda: dz.book_process_noise(F, Q, dt)),
            ("Van Loan Φ, Q_k", lambda: dz.van_loan(F, Q, dt)),
            ("expm(FΔt) alone", lambda: expm(F * dt))]
    for label, fn in rows:
        t = min(timeit.repeat(fn, number=200, repeat=5)) / 200
        print(f"  {label:26s} {t * 1e6:8.1f} µs")


if __name__ == "__main__":
    for name in ("seed", "mems21"):
        accuracy_table(name)
        slope_table(name)
        timing(name)
