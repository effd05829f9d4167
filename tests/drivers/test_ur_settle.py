"""The UR driver's settle criterion on synthetic samples (no library, no emulator)."""
import numpy as np
import pytest

from drivers.ur import UROptions, Settle


@pytest.mark.unit
def test_settle_window_rejects_ringing_and_accepts_noise():
    """The window criterion on synthetic samples at 500 Hz: white noise passes, an undamped 7 Hz oscillation of
    0.02 deg never does (the per-sample |qd| criterion would refuse both)."""
    rng = np.random.default_rng(11)

    class _W:
        o = UROptions(settle_hold_s=0.25)

        class rtde_r:
            @staticmethod
            def getTimestamp():
                return 0.0

    def run(ring_rad: float) -> float | None:
        settle = Settle(_W(), [0.0] * 6)
        for k in range(1500):
            t = k / 500.0
            q = rng.normal(0, 2e-5, 6) + ring_rad * np.cos(2 * np.pi * 7 * t)
            qd = rng.normal(0, 1e-3, 6) - ring_rad * 2 * np.pi * 7 * np.sin(2 * np.pi * 7 * t)
            if settle._evaluate(q, qd, t) is not None:
                return t
        return None
    assert run(0.0) is not None and run(0.0) < 0.3
    qd = rng.normal(0, 1e-3, (500, 6))
    assert np.mean(np.all(np.abs(qd) < 1e-4, axis=1)) < 0.01     # a per-sample |qd| < 1e-4 test almost never passes
    assert run(np.radians(0.02)) is None
