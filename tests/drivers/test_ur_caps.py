"""The UR driver's speed cap on random joint moves (no library, no emulator): at the speed it would send, no point of
the tool (the TCP and points ``tool_radius_mm`` from it) moves faster than the TCP cap anywhere on the path."""
import numpy as np
import pytest

from drivers.ur import UR_DH, UROptions, dh_points, Worker


def _worker(model: str, tcp_m, tool_radius_mm: float) -> Worker:
    w = Worker(None, "unused", UROptions(tool_radius_mm=tool_radius_mm))
    w.dh, w.tcp_offset, w.rated_rad_s = UR_DH[model], [*tcp_m, 0.0, 0.0, 0.0], np.radians(120)
    return w


def _peak_speed(w: Worker, q0, q1, omega: float, radius_m: float) -> float:
    """Highest point speed (m/s) on a dense path with the leading joint at omega (the trapezoid's cruise)."""
    s = np.linspace(0.0, 1.0, 1201)[:, None]
    q = q0 + s * (q1 - q0)
    dt = np.max(np.abs(q1 - q0)) / omega / (len(s) - 1)
    peak = 0.0
    for d in [np.zeros(3)] + [sign * radius_m * a for a in np.eye(3) for sign in (1, -1)]:
        p = dh_points(q, w.dh, np.asarray(w.tcp_offset[:3]) + d)
        peak = max(peak, float(np.linalg.norm(np.diff(p, axis=0), axis=1).max()) / dt)
    return peak


@pytest.mark.parametrize("model", [pytest.param("UR10", marks=pytest.mark.system),      # one model in the unit tier
                                   pytest.param("UR5e", marks=pytest.mark.unit),
                                   pytest.param("UR16e", marks=pytest.mark.system)])
def test_no_point_of_the_tool_exceeds_the_tcp_cap(model):
    rng = np.random.default_rng(13)
    w = _worker(model, (0.0, 0.02, 0.12), tool_radius_mm=150.0)
    ratios = []
    for _ in range(30):
        q0 = rng.uniform(-np.pi, np.pi, 6)
        q1 = q0 + rng.uniform(-1.5, 1.5, 6) * (rng.random(6) < 0.7)
        cap = rng.uniform(0.05, 0.5)                                   # m/s
        omega = w._capped_speed(list(q0), list(q1), 3.0, cap, 100.0)
        if np.max(np.abs(q1 - q0)) < 1e-9:
            continue
        ratios.append(_peak_speed(w, q0, q1, omega, 0.15) / cap)
    assert max(ratios) <= 1.0 and np.median(ratios) > 0.8          # safe, and not needlessly slow


@pytest.mark.unit
def test_joint_cap_and_wrist_moves():
    w = _worker("UR10", (0.0, 0.0, 0.0), tool_radius_mm=0.0)
    q0 = np.array([0.0, -1.57, 1.57, -1.57, -1.57, 0.0])
    wrist = q0 + [0, 0, 0, 0, 0, 1.0]                                 # rotates the flange about its own axis
    assert w._capped_speed(list(q0), list(wrist), 3.0, 0.1, 30.0) == pytest.approx(0.3 * np.radians(120))
    w_tool = _worker("UR10", (0.0, 0.0, 0.0), tool_radius_mm=200.0)    # a tool 200 mm out does move
    assert w_tool._capped_speed(list(q0), list(wrist), 3.0, 0.1, 100.0) == pytest.approx(0.9 * 0.1 / 0.2, rel=1e-3)
