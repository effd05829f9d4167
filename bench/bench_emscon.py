"""emScon tracker in a whole campaign: device-reported covariance vs the spec model as calibration weights.

For two simulated cells (seeds 1 and 2 of configs/irb2600.yaml, coarse grid, 30 test points), `campaign run` measures
with the emScon driver against the emScon emulator (which measures the simulated cell and reports std devs and
covariances), then the same log is calibrated twice: weights from the device covariance (what `campaign run` does
when the tracker reports it) and from the config's spec model. Printed: held-out test RMS (kinematic stage) of both,
the noise floor, and the wall time of the measurement phase per point.
Run: OPENBLAS_NUM_THREADS=1 python bench/bench_emscon.py
"""
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from campaign.run import devices  # noqa: E402
from campaign.cli import main  # noqa: E402
from campaign.config.load import load_cell  # noqa: E402
from campaign.data.log_dataset import dataset_from_log  # noqa: E402
from campaign.calibrate.stages import calibrate_dataset  # noqa: E402
from campaign.run.log_reader import read_log  # noqa: E402
from drivers.emulators.emscon_server import EmsconEmulator  # noqa: E402
from tests.campaign.helpers import small_config  # noqa: E402

SMALL = {"plan.test.count": 30, "plan.check_poses": {"count": 0, "every_n_points": 50},
         "tracker.measurement.samples": 2, "tracker.measurement.settle_s": 0.0, "calibration.residual": "none"}


def one(tmp: Path, seed: int) -> None:
    tmp.mkdir(parents=True, exist_ok=True)
    world = devices.mock_world(load_cell(small_config(tmp, **SMALL, **{"simulation.seed": seed})))
    world.faults = {}
    devices.mock_world = lambda cell: world
    with EmsconEmulator(lambda: world.p_smr_tracker_mm + world.point_error_mm, seed=seed) as emu:
        path = small_config(tmp, **SMALL, **{"simulation.seed": seed, "tracker.url": emu.url,
                                             "tracker.options": {"meas_time_ms": 10}})
        t0 = time.perf_counter()
        assert main(["run", str(path), "--out", str(tmp / f"run{seed}")]) == 0
        wall = time.perf_counter() - t0
    cell = load_cell(path)
    ds = dataset_from_log(read_log(tmp / f"run{seed}"))
    device = calibrate_dataset(ds, cell).report
    spec = calibrate_dataset(dataclasses.replace(ds, cov_mm2=None), cell).report
    rms = lambda r: r.stages["kinematic"].test.rms_mm  # noqa: E731
    print(f"seed {seed}: {len(ds.point_id)} points; test RMS device weights {rms(device):.4f} mm, spec weights "
          f"{rms(spec):.4f} mm (ratio {rms(device) / rms(spec):.3f}); noise floor {device.noise_floor_mm:.4f} mm; "
          f"run incl. calibration {wall:.1f} s ({1000 * wall / len(ds.point_id):.0f} ms/point)")


if __name__ == "__main__":
    with tempfile.TemporaryDirectory() as d:
        for s in (1, 2):
            one(Path(d) / f"s{s}", s)
