"""Plots are written as readable PNG files (content checked by eye once, see docs/results)."""
import numpy as np
import pymap3d
from scipy.spatial.transform import Rotation

from ins_gnss_ros.trial.evaluate import Trajectory, evaluate
from ins_gnss_ros.trial.plots import plot_innovations, write_plots

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _trajectory(t, east_error=0.0, yaw_error=0.0, covariance=False):
    w = 2 * np.pi / 60.0
    lat, lon, h = pymap3d.enu2geodetic(100 * np.cos(w * t) + east_error, 100 * np.sin(w * t),
                                       0 * t, 0.7, 0.2, 50.0, deg=False)
    yaw = w * t + np.pi / 2 + yaw_error
    q = Rotation.from_euler("z", yaw[:, None]).as_quat()[:, [3, 0, 1, 2]]
    vel = np.column_stack([-100 * w * np.sin(w * t), 100 * w * np.cos(w * t), 0 * t])
    extra = {}
    if covariance:
        n = len(t)
        extra = {"pos_cov_enu": np.broadcast_to(np.eye(3) * 0.25, (n, 3, 3)),
                 "vel_cov_enu": np.broadcast_to(np.eye(3) * 0.01, (n, 3, 3)),
                 "att_cov": np.broadcast_to(np.eye(3) * 1e-4, (n, 3, 3))}
    return Trajectory(time=t, lat=lat, lon=lon, height=h, vel_enu=vel, q_nb=q, **extra)


def test_write_plots(tmp_path):
    t = np.arange(0.0, 120.0, 0.1)
    windows = np.array([[30.0, 45.0], [75.0, 90.0]])
    drift = np.where((t >= 30) & (t < 45), 0.02 * (t - 30) ** 2, 0.0)
    truth = _trajectory(t[::5])
    estimate = _trajectory(t, east_error=drift + 0.1 * np.sin(t), yaw_error=0.01 * np.sin(t),
                           covariance=True)
    result = evaluate(estimate, truth, windows)
    paths = write_plots(result, estimate, truth, tmp_path / "plots", windows)
    assert [p.name for p in paths] == ["trajectory.png", "errors.png", "heading.png"]
    for path in paths:
        data = path.read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 20_000


def test_innovations_plot(tmp_path):
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 60.0, 0.25)
    innovations = rng.normal(0, [0.5, 0.5, 1.0], (len(t), 3))
    nis = np.sum((innovations / [0.5, 0.5, 1.0]) ** 2, axis=1)
    path = plot_innovations(t, innovations, tmp_path / "innovations.png", nis=nis,
                            labels=["east (m)", "north (m)", "up (m)"],
                            windows=np.array([[20.0, 35.0]]))
    assert path.read_bytes().startswith(PNG_MAGIC)
