"""RWS requests per second while the ABB driver waits for a move, against the RWS emulator (1.0 and 2.0).

Compares the driver's polling (one ``cal_state`` read per poll, the execution state once per ``health_s``, paced to
``max_poll_rate_hz``) with the previous scheme in the same run: ``cal_done_seq``, ``cal_err_seq`` and ``cal_ack_seq``
read separately every 0.2 s, plus controller and execution state every second. Each move is about 3.7 s
(74 deg at 20 deg/s). Prints the median requests/s over the moves and the ratio.

Run: ``OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD python3 bench/bench_rws_polling.py``
"""
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from drivers import registry  # noqa: E402
from drivers.abb_rws import AbbRwsRobot, Deadline, parse_num  # noqa: E402
from drivers.emulators.rws_server import RwsEmulator  # noqa: E402

USER, PASSWORD = "bench", "bench-pw"
ENV = {"RWS_USER": USER, "RWS_PASSWORD": PASSWORD}
TARGETS = [(74, 0, 0, 0, 30, 0), (0, 0, 0, 0, 30, 0)]


class LegacyPolling(AbbRwsRobot):
    """The previous wait loop: three symbol reads per 0.2 s poll and two state reads per second."""

    def _await_done(self, seq: int, what: str, move_s: float) -> None:
        deadline, health = Deadline(self.opts.timeouts.ack_s + move_s), Deadline(1.0)
        while not deadline.expired():
            if int(parse_num(self._read("cal_done_seq"))) == seq:
                return
            if int(parse_num(self._read("cal_err_seq"))) == seq:
                self._raise_rejected(seq, what)
            int(parse_num(self._read("cal_ack_seq")))
            if health.expired():
                self._ctrlstate()
                self._exec_state()
                health = Deadline(1.0)
            self._sleep(0.2)
        self._fail(seq, what, "timeout")


def _rates(emu: RwsEmulator, robot: AbbRwsRobot, moves: int) -> tuple[list[float], list[float]]:
    """Per move (from the call to its return): all requests/s (the request's writes included) and the polling
    GETs/s alone."""
    total, polls = [], []
    for i in range(moves):
        n0, t0 = len(emu.requests), time.perf_counter()
        robot.move_joints(TARGETS[i % 2])
        dt, seen = time.perf_counter() - t0, emu.requests[n0:]
        total.append(len(seen) / dt)
        polls.append(sum(1 for r in seen if r[0] == "GET") / dt)
    return total, polls


def main(moves: int = 4) -> None:
    for version in (1, 2):
        with RwsEmulator(version, user=USER, password=PASSWORD, joint_speed_deg_s=20.0) as emu:
            results = {}
            for name, cls in (("driver", AbbRwsRobot), ("legacy", LegacyPolling)):
                base = registry.open_robot(emu.url, {"settle_s": 0.0}, environ=ENV)
                robot = cls(emu.url, base.opts, base.session._credentials)
                robot.connect()
                try:
                    results[name] = _rates(emu, robot, moves)
                finally:
                    robot.close()
            (drv, drv_get), (old, old_get) = results["driver"], results["legacy"]
            print(f"RWS {version}.0, {moves} moves of ~3.7 s, requests/s median (max): driver {statistics.median(drv):.2f} "
                  f"({max(drv):.2f}) of which polls {statistics.median(drv_get):.2f} ({max(drv_get):.2f}); "
                  f"previous polling {statistics.median(old):.2f} ({max(old):.2f}); "
                  f"ratio {statistics.median(old) / statistics.median(drv):.1f}x fewer")


if __name__ == "__main__":
    main()
