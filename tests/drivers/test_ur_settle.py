"""The UR worker on synthetic samples (no library, no emulator): the settle criterion and the motion-state checks."""
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


class _LaggingReceive:
    """RTDE receive side whose samples show the protective stop only from sample ``shows_at`` on: under load its
    buffered samples are older than the control side's, which already saw the script end."""

    def __init__(self, shows_at: int) -> None:
        self.sample, self.shows_at = 0, shows_at

    def isConnected(self):
        return True

    def getTimestamp(self):
        self.sample += 1                       # every read finds one newer sample
        return 0.002 * self.sample

    def getSafetyMode(self):
        return 3 if self.sample >= self.shows_at else 1

    def getRobotMode(self):
        return 7

    def getRuntimeState(self):
        return 1

    def getJointTemperatures(self):
        return [30.0] * 6


class _DeadScript:
    def isConnected(self):
        return True

    def isProgramRunning(self):
        return False


@pytest.mark.unit
@pytest.mark.parametrize("shows_at, expected", [(5, "PROTECTIVE_STOP"), (10**9, "script is not running")])
def test_a_dead_script_is_explained_by_a_stop_that_lagging_samples_show_late(shows_at, expected):
    """The CI failure of 2026-11-29: one fresh sample still said NORMAL, so a protective stop was reported as a
    dead script. Samples are watched for up to ``stale_after_s`` before the script alone is blamed."""
    from drivers.ur_worker import Worker, _Failure
    w = Worker(None, "127.0.0.1", UROptions(stale_after_s=0.05))
    w.rtde_r, w.rtde_c = _LaggingReceive(shows_at), _DeadScript()
    with pytest.raises(_Failure, match=expected) as err:
        w._check_motion_state()
    assert err.value.kind == "motion"
    assert w.pstop_seen == (expected == "PROTECTIVE_STOP")
