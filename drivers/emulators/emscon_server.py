"""Leica emScon laser-tracker emulator (binary C structs over TCP), written from the public header ``ES_C_API_Def.h``.

Serves one client at a time on 127.0.0.1. Implements the commands a stationary single-point client uses:
GetSystemStatus, Initialize, SetUnits (all length, temperature and pressure units), SetCoordinateSystemType (RHR),
SetMeasurementMode (stationary), SetStationaryModeParams, SetSystemSettings / GetSystemSettings,
SetEnvironmentParams / GetEnvironmentParams, SetReflector / GetReflector / GetReflectors, SetStatisticMode
(extended -> ``SingleMeasResult2T`` with covariances), StartMeasurement (command reply, then the result packet),
GoPosition, FindReflector, ClearCommandQueue; anything else is answered with ``ES_RS_NotImplemented``.
Settings commands are followed by the matching ``SystemStatusChangeT`` as a tracker server sends them.

The SMR position comes from ``position_source()`` (mm, tracker frame: the simulated cell); each StartMeasurement
adds Gaussian noise drawn from a spherical model (range and transverse sigma a + b * distance) and reports that
model's std devs and covariances, plus the temperature, pressure and humidity used (weather station, or the manual
values when the weather monitor is set to "not connected").

Tracking model (what reacquisition has to deal with): while the beam is intact the tracker follows the SMR. A beam
break leaves the tracker pointing where the SMR was at the previous measurement (the beam was lost during the robot
move); FindReflector finds the SMR only if the tracker points within ``search_radius_mm`` of it, so a client must
GoPosition to a predicted position first.

Faults (one-shot with ``inject(name)``, consumed by the next StartMeasurement; or per-measurement probabilities):
``beam_break`` (status change MeasStatus_NotReady + unsolicited ``ErrorResponseT`` with
ES_RS_MeasurementStatusNotReady; measurements fail until a FindReflector succeeds), ``lost_reflector`` (the same, but
FindReflector never succeeds), ``late`` (the result packet is sent ``late_s`` later), ``garbage`` (junk bytes
instead of the reply), ``disconnect`` (the server closes the connection), ``not_initialised`` (the tracker loses its
initialisation: ES_RS_TrackerNotInitialized until Initialize), ``warm_up`` (one ES_RS_SensorNotWarmedUp reply).

Run standalone: ``python -m drivers.emulators.emscon_server --port PORT`` (port 0: any free port, printed on the
first stdout line with ``--print-port``); it serves until killed, interrupted or its stdin is closed
(``--ignore-stdin`` to disable that). It measures a fixed point; a caller passes ``serve(args, position_source)``
its own SMR position (``python -m campaign.run.emscon_cell CONFIG`` measures a campaign config's simulated cell).
"""
from __future__ import annotations

import argparse
import math
import random
import socket
import sys
from collections import deque
from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np

from drivers.emscon_protocol import (AU_DEGREE, COMMAND_CT, CS_RHR, C_CLEAR_COMMAND_QUEUE, C_FIND_REFLECTOR,
                                     C_GET_ENVIRONMENT_PARAMS, C_GET_REFLECTOR, C_GET_REFLECTORS,
                                     C_GET_SYSTEM_SETTINGS, C_GET_SYSTEM_STATUS, C_GO_POSITION, C_INITIALIZE,
                                     C_SET_COORDINATE_SYSTEM_TYPE, C_SET_ENVIRONMENT_PARAMS, C_SET_MEASUREMENT_MODE,
                                     C_SET_REFLECTOR, C_SET_STATIONARY_MODE_PARAMS, C_SET_STATISTIC_MODE,
                                     C_SET_SYSTEM_SETTINGS, C_SET_UNITS, C_START_MEASUREMENT, C_STOP_MEASUREMENT,
                                     DEFAULT_PORT, FramingError, HU_RH, LU_MILLIMETER, MM_STATIONARY, PU_MBAR,
                                     PacketReader, RS_ALL_OK, RS_MEASUREMENT_STATUS_NOT_READY,
                                     RS_METEO_DATA_OUT_OF_RANGE, RS_NOT_IMPLEMENTED, RS_SENSOR_NOT_WARMED_UP,
                                     RS_TRACKER_NOT_INITIALIZED, RS_WRONG_PARAMETER, SM_EXTENDED, SM_STANDARD,
                                     SSC_MEAS_STATUS_NOT_READY, SSC_MEAS_STATUS_READY, TPS_INITIALIZED, TU_CELSIUS,
                                     WMS_NOT_CONNECTED, WMS_READ_AND_CALCULATE, WMS_READ_ONLY, decode_command,
                                     encode_error, encode_meas_result, encode_reply, encode_status_change)
from robocal.measure.noise import TrackerUncertainty

from .faults import FaultDeck
from .tcp import TcpServer, wait_for_shutdown

HOST = "127.0.0.1"
POLL_S = 0.02
DEFAULT_POINT_MM = (2500.0, -400.0, 300.0)
FAULTS = ("beam_break", "lost_reflector", "late", "garbage", "disconnect", "not_initialised", "warm_up")
GARBAGE = b"\x7f\xff\xff\x7fGARBAGE\x00\x01\x02\x03garbage-garbage"
LENGTH_PER_MM = {0: 1e-3, 1: 1.0, 2: 1e3, 3: 1 / 304.8, 4: 1 / 914.4, 5: 1 / 25.4}
PRESSURE_PER_MBAR = {0: 1.0, 1: 1.0, 2: 0.1, 3: 0.750062, 4: 0.0145038, 5: 0.401865, 6: 0.0295300}
REFLECTORS = ((1, 5, 19.05, "RRR 1.5in"), (2, 6, 6.35, "RRR 0.5in"), (3, 11, 11.1125, "RRR 7/8in"),
              (4, 2, 0.0, "CatsEye"))
STATUS_AFTER = {C_SET_UNITS: 6, C_SET_REFLECTOR: 7, C_SET_SYSTEM_SETTINGS: 8, C_SET_COORDINATE_SYSTEM_TYPE: 12,
                C_SET_MEASUREMENT_MODE: 17, C_SET_STATIONARY_MODE_PARAMS: 18, C_SET_STATISTIC_MODE: 24,
                C_SET_ENVIRONMENT_PARAMS: 2}

PositionSource = Callable[[], Sequence[float]]


@dataclass(frozen=True)
class Out:
    """Send ``data`` after ``delay_s`` s; ``disconnect``: close the connection instead."""
    data: bytes = b""
    delay_s: float = 0.0
    disconnect: bool = False


@dataclass(frozen=True)
class NoiseModel(TrackerUncertainty):
    """1-sigma noise of one stationary measurement (``coverage_k`` 1): robocal's spherical tracker model, range and
    transverse ``a_um + b_um_per_m * distance``, with the emulator's defaults."""
    transverse_a_um: float = 3.0
    transverse_b_um_per_m: float = 1.0
    range_a_um: float = 2.0
    range_b_um_per_m: float = 0.5
    coverage_k: float = 1.0

    def covariance_mm2(self, p_mm: Sequence[float]) -> list[list[float]]:
        """(3, 3) covariance in mm^2 at ``p_mm`` (tracker frame), as nested lists."""
        return self.covariance(np.asarray(p_mm, float))[0].tolist()


def _cholesky3(c: list[list[float]]) -> list[list[float]]:
    L = [[0.0] * 3 for _ in range(3)]
    for i in range(3):
        for j in range(i + 1):
            s = c[i][j] - sum(L[i][k] * L[j][k] for k in range(j))
            L[i][j] = math.sqrt(max(s, 0.0)) if i == j else (s / L[j][j] if L[j][j] > 0 else 0.0)
    return L


class EmsconDevice:
    """The emScon server without I/O: ``respond(packet) -> [Out]``. Fault settings are thread-safe."""

    def __init__(self, position_source: PositionSource | None = None, *, seed: int = 0,
                 noise: NoiseModel | None = None, environment: tuple[float, float, float] = (20.5, 1008.0, 42.0),
                 initialised: bool = False, init_time_s: float = 0.02, search_radius_mm: float = 60.0,
                 late_s: float = 1.0, meas_time_scale: float = 0.0,
                 fault_probabilities: Mapping[str, float] | None = None, serial: int = 754321) -> None:
        self._position = position_source or (lambda: DEFAULT_POINT_MM)
        self.noise = noise or NoiseModel()
        self.station_env = tuple(environment)
        self.manual_env = (20.0, 1013.25, 50.0)
        self.initialised, self.init_time_s = initialised, init_time_s
        self.search_radius_mm, self.late_s, self.meas_time_scale = search_radius_mm, late_s, meas_time_scale
        self.serial = serial
        self._rng = random.Random(seed)
        self._deck = FaultDeck(FAULTS, random.Random(seed + 7919))
        bad = set(fault_probabilities or {}) - set(FAULTS)
        if bad:
            raise ValueError(f"unknown faults {sorted(bad)} (expected {', '.join(FAULTS)})")
        self.fault_probabilities = dict(fault_probabilities or {})
        self.units = (LU_MILLIMETER, AU_DEGREE, TU_CELSIUS, PU_MBAR, HU_RH)
        self.settings = [WMS_READ_AND_CALCULATE, 0, 0, 1, 1, 0, 0, 1, 1]
        self.coord_type, self.meas_mode, self.meas_time_ms, self.use_adm = CS_RHR, MM_STATIONARY, 1000, 1
        self.statistic_mode, self.reflector_id = SM_STANDARD, 1
        self.beam_ok, self.reflector_lost = True, False
        self.aim_mm: tuple[float, float, float] | None = None     # where the tracker points when the beam is broken
        self.last_true_mm: tuple[float, float, float] | None = None
        self.commands: deque[int] = deque(maxlen=10000)
        self.last_truth: dict | None = None                       # the last measurement's truth (for tests)

    # -- fault control
    def inject(self, *names: str) -> None:
        self._deck.inject(*names)

    def _draw_fault(self) -> str | None:
        probs = dict(self.fault_probabilities)
        return self._deck.draw(lambda name: probs.get(name, 0.0))

    # -- dispatch
    def respond(self, packet: bytes) -> list[Out]:
        """Replies to one whole command packet."""
        try:
            command, params = decode_command(packet)
        except FramingError:
            return [Out(encode_reply(COMMAND_CT.unpack_from(packet)[2], RS_WRONG_PARAMETER))]
        self.commands.append(command)
        handler = self._handlers().get(command)
        if handler is None:
            return [Out(encode_reply(command, RS_NOT_IMPLEMENTED))]
        return handler(*params)

    def _handlers(self) -> dict[int, Callable[..., list[Out]]]:
        return {C_GET_SYSTEM_STATUS: self._get_system_status, C_INITIALIZE: self._initialize,
                C_SET_UNITS: self._set_units, C_SET_COORDINATE_SYSTEM_TYPE: self._set_coord,
                C_SET_MEASUREMENT_MODE: self._set_mode, C_SET_STATIONARY_MODE_PARAMS: self._set_stationary,
                C_SET_SYSTEM_SETTINGS: self._set_settings, C_GET_SYSTEM_SETTINGS: self._get_settings,
                C_SET_ENVIRONMENT_PARAMS: self._set_env, C_GET_ENVIRONMENT_PARAMS: self._get_env,
                C_SET_REFLECTOR: self._set_reflector, C_GET_REFLECTOR: self._get_reflector,
                C_GET_REFLECTORS: self._get_reflectors, C_SET_STATISTIC_MODE: self._set_statistic,
                C_START_MEASUREMENT: self._start_measurement, C_GO_POSITION: self._go_position,
                C_FIND_REFLECTOR: self._find_reflector, C_CLEAR_COMMAND_QUEUE: self._ok(C_CLEAR_COMMAND_QUEUE),
                C_STOP_MEASUREMENT: self._ok(C_STOP_MEASUREMENT)}

    def _ok(self, command: int) -> Callable[..., list[Out]]:
        return lambda *_: [Out(encode_reply(command, RS_ALL_OK))]

    def _changed(self, command: int, status: int = RS_ALL_OK) -> list[Out]:
        out = [Out(encode_reply(command, status))]
        if status == RS_ALL_OK and command in STATUS_AFTER:
            out.append(Out(encode_status_change(STATUS_AFTER[command])))
        return out

    # -- commands
    def _get_system_status(self) -> list[Out]:
        tps = TPS_INITIALIZED if self.initialised else 4           # ES_TPS_CompensationSet
        return [Out(encode_reply(C_GET_SYSTEM_STATUS, RS_ALL_OK, RS_ALL_OK, tps, 3, 2, 3, 8, 500,
                                   self.settings[0], 0, self.serial))]

    def _initialize(self) -> list[Out]:
        self.initialised, self.beam_ok, self.aim_mm = True, not self.reflector_lost, None
        return [Out(encode_reply(C_INITIALIZE, RS_ALL_OK), delay_s=self.init_time_s)]

    def _set_units(self, length, angle, temp, pressure, humidity) -> list[Out]:
        if length not in LENGTH_PER_MM or angle not in (0, 1, 2) or temp not in (0, 1) \
                or pressure not in PRESSURE_PER_MBAR or humidity != HU_RH:
            return [Out(encode_reply(C_SET_UNITS, RS_WRONG_PARAMETER))]
        self.units = (length, angle, temp, pressure, humidity)
        return self._changed(C_SET_UNITS)

    def _set_coord(self, kind) -> list[Out]:
        if kind != CS_RHR:
            return [Out(encode_reply(C_SET_COORDINATE_SYSTEM_TYPE, RS_NOT_IMPLEMENTED))]
        self.coord_type = kind
        return self._changed(C_SET_COORDINATE_SYSTEM_TYPE)

    def _set_mode(self, mode) -> list[Out]:
        if mode != MM_STATIONARY:
            return [Out(encode_reply(C_SET_MEASUREMENT_MODE, RS_NOT_IMPLEMENTED))]
        self.meas_mode = mode
        return self._changed(C_SET_MEASUREMENT_MODE)

    def _set_stationary(self, meas_time_ms, use_adm) -> list[Out]:
        if not 0 < meas_time_ms <= 100000:
            return [Out(encode_reply(C_SET_STATIONARY_MODE_PARAMS, RS_WRONG_PARAMETER))]
        self.meas_time_ms, self.use_adm = meas_time_ms, use_adm
        return self._changed(C_SET_STATIONARY_MODE_PARAMS)

    def _set_settings(self, *values) -> list[Out]:
        if values[0] not in (WMS_NOT_CONNECTED, WMS_READ_ONLY, WMS_READ_AND_CALCULATE):
            return [Out(encode_reply(C_SET_SYSTEM_SETTINGS, RS_WRONG_PARAMETER))]
        self.settings = list(values[:7]) + self.settings[7:]            # bHasNivel, bHasVideoCamera are read-only
        return self._changed(C_SET_SYSTEM_SETTINGS)

    def _get_settings(self) -> list[Out]:
        return [Out(encode_reply(C_GET_SYSTEM_SETTINGS, RS_ALL_OK, *self.settings))]

    def _set_env(self, temperature, pressure, humidity) -> list[Out]:
        t_c = self._temp_to_c(temperature)
        p_mbar = pressure / PRESSURE_PER_MBAR[self.units[3]]
        if not (-10 <= t_c <= 50 and 500 <= p_mbar <= 1200 and 0 <= humidity <= 100):
            return [Out(encode_reply(C_SET_ENVIRONMENT_PARAMS, RS_METEO_DATA_OUT_OF_RANGE))]
        self.manual_env = (t_c, p_mbar, humidity)
        return self._changed(C_SET_ENVIRONMENT_PARAMS)

    def _get_env(self) -> list[Out]:
        return [Out(encode_reply(C_GET_ENVIRONMENT_PARAMS, RS_ALL_OK, *self._env_in_units()))]

    def _set_reflector(self, reflector_id) -> list[Out]:
        if reflector_id not in [r[0] for r in REFLECTORS]:
            return [Out(encode_reply(C_SET_REFLECTOR, RS_WRONG_PARAMETER))]
        self.reflector_id = reflector_id
        return self._changed(C_SET_REFLECTOR)

    def _get_reflector(self) -> list[Out]:
        return [Out(encode_reply(C_GET_REFLECTOR, RS_ALL_OK, self.reflector_id))]

    def _get_reflectors(self) -> list[Out]:
        k = LENGTH_PER_MM[self.units[0]]
        return [Out(encode_reply(C_GET_REFLECTORS, RS_ALL_OK, len(REFLECTORS), rid, ttype, offset_mm * k,
                                   name.encode("utf-16-le"))) for rid, ttype, offset_mm, name in REFLECTORS]

    def _set_statistic(self, stationary, continuous) -> list[Out]:
        if stationary not in (SM_STANDARD, SM_EXTENDED) or continuous not in (SM_STANDARD, SM_EXTENDED):
            return [Out(encode_reply(C_SET_STATISTIC_MODE, RS_WRONG_PARAMETER))]
        self.statistic_mode = stationary
        return self._changed(C_SET_STATISTIC_MODE)

    def _go_position(self, x, y, z, use_adm) -> list[Out]:
        if not self.initialised:
            return [Out(encode_reply(C_GO_POSITION, RS_TRACKER_NOT_INITIALIZED))]
        k = LENGTH_PER_MM[self.units[0]]
        self.aim_mm = (x / k, y / k, z / k)
        return [Out(encode_reply(C_GO_POSITION, RS_ALL_OK))]

    def _find_reflector(self, approx_distance) -> list[Out]:
        if not self.initialised:
            return [Out(encode_reply(C_FIND_REFLECTOR, RS_TRACKER_NOT_INITIALIZED))]
        true = self._true()
        if self.beam_ok or (not self.reflector_lost and self.aim_mm is not None
                            and math.dist(self.aim_mm, true) <= self.search_radius_mm):
            self.beam_ok, self.aim_mm = True, None
            return [Out(encode_reply(C_FIND_REFLECTOR, RS_ALL_OK)),
                    Out(encode_status_change(SSC_MEAS_STATUS_READY))]
        return [Out(encode_reply(C_FIND_REFLECTOR, RS_MEASUREMENT_STATUS_NOT_READY))]

    def _start_measurement(self) -> list[Out]:
        if not self.initialised:
            return [Out(encode_reply(C_START_MEASUREMENT, RS_TRACKER_NOT_INITIALIZED))]
        fault = self._draw_fault()
        if fault == "disconnect":
            return [Out(disconnect=True)]
        if fault == "garbage":
            return [Out(GARBAGE)]
        if fault == "warm_up":
            return [Out(encode_reply(C_START_MEASUREMENT, RS_SENSOR_NOT_WARMED_UP))]
        if fault == "not_initialised":
            self.initialised = False
            return [Out(encode_reply(C_START_MEASUREMENT, RS_TRACKER_NOT_INITIALIZED))]
        if fault in ("beam_break", "lost_reflector"):
            self.beam_ok, self.reflector_lost = False, fault == "lost_reflector"
            self.aim_mm = self.last_true_mm or (0.0, 0.0, 1000.0)
            return [Out(encode_reply(C_START_MEASUREMENT, RS_ALL_OK)),
                    Out(encode_status_change(SSC_MEAS_STATUS_NOT_READY)),
                    Out(encode_error(C_START_MEASUREMENT, RS_MEASUREMENT_STATUS_NOT_READY))]
        if not self.beam_ok:
            return [Out(encode_reply(C_START_MEASUREMENT, RS_MEASUREMENT_STATUS_NOT_READY))]
        delay = self.meas_time_ms / 1000.0 * self.meas_time_scale + (self.late_s if fault == "late" else 0.0)
        return [Out(encode_reply(C_START_MEASUREMENT, RS_ALL_OK)), Out(self._result(), delay_s=delay)]

    # -- measurement
    def _true(self) -> tuple[float, float, float]:
        return tuple(float(v) for v in self._position())

    def _result(self) -> bytes:
        true = self._true()
        self.last_true_mm = true
        cov = self.noise.covariance_mm2(true)
        L = _cholesky3(cov)
        z = [self._rng.gauss(0.0, 1.0) for _ in range(3)]
        meas = [true[i] + sum(L[i][k] * z[k] for k in range(3)) for i in range(3)]
        env_c = self._env_used()
        self.last_truth = {"true_mm": true, "measured_mm": tuple(meas), "cov_mm2": cov, "environment": env_c}
        k = LENGTH_PER_MM[self.units[0]]
        std = [math.sqrt(cov[i][i]) * k for i in range(3)]
        covar = [cov[0][1] * k * k, cov[0][2] * k * k, cov[1][2] * k * k]
        return encode_meas_result([v * k for v in meas], std, covar, self._env_in_units(),
                                    extended=self.statistic_mode == SM_EXTENDED)

    def _env_used(self) -> tuple[float, float, float]:
        return self.manual_env if self.settings[0] == WMS_NOT_CONNECTED else self.station_env

    def _env_in_units(self) -> tuple[float, float, float]:
        t_c, p_mbar, h = self._env_used()
        t = t_c * 1.8 + 32.0 if self.units[2] == 1 else t_c
        return (t, p_mbar * PRESSURE_PER_MBAR[self.units[3]], h)

    def _temp_to_c(self, value: float) -> float:
        return (value - 32.0) / 1.8 if self.units[2] == 1 else value


class EmsconEmulator(TcpServer):
    """The device served over TCP on 127.0.0.1 by one background thread; a context manager.

    ``port=0`` picks a free port (``.port``; ``.url`` is the driver URL). ``connections`` and ``packets_sent`` count
    accepted clients and packets sent. Keyword arguments go to ``EmsconDevice``.
    """
    thread_name, label = "emscon-emulator", "emScon emulator"
    poll_s = POLL_S

    def __init__(self, position_source: PositionSource | None = None, port: int = 0, **device_options) -> None:
        super().__init__(HOST, port)
        self.device = EmsconDevice(position_source, **device_options)
        self.packets_sent = 0

    @property
    def url(self) -> str:
        return f"emscon://{HOST}:{self.port}"

    def inject(self, *names: str) -> None:
        self.device.inject(*names)

    def stop(self, timeout_s: float = 3.0) -> None:
        super().stop(timeout_s)

    def _serve_client(self, conn: socket.socket) -> None:
        conn.settimeout(2.0)
        reader = PacketReader()
        for data in self._received(conn, 65536):
            reader.feed(data)
            try:
                while (packet := reader.next_packet()) is not None:
                    if not self._answer(conn, packet):
                        return
            except FramingError:
                return                               # a client out of step: drop it, as a server would

    def _answer(self, conn: socket.socket, packet: bytes) -> bool:
        for out in self.device.respond(packet):
            if not self._deliver(conn, out.data, out.delay_s, out.disconnect):
                return False
            self.packets_sent += 1
        return True


# ------------------------------------------------------------------------------------------------- command line

def parser(prog: str = "python -m drivers.emulators.emscon_server",
           description: str = "Leica emScon laser-tracker emulator on 127.0.0.1.") -> argparse.ArgumentParser:
    """The emulator's command-line options (a caller may add its own before ``serve``)."""
    p = argparse.ArgumentParser(prog=prog, description=description)
    p.add_argument("--port", type=int, default=DEFAULT_PORT, help="TCP port (0: any free port; default 700)")
    p.add_argument("--print-port", action="store_true", help="print the bound port as the first stdout line")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--initialised", action="store_true", help="start initialised (default: Initialize needed)")
    p.add_argument("--meas-time-scale", type=float, default=0.0,
                   help="real seconds per second of the configured measurement time (0: answer at once)")
    p.add_argument("--late-s", type=float, default=1.0, help="delay of a late result (s)")
    p.add_argument("--faults", default="", help="per-measurement probabilities, e.g. beam_break=0.05,garbage=0.01")
    p.add_argument("--ignore-stdin", action="store_true", help="keep serving when stdin is closed")
    return p


def _fault_probabilities(text: str) -> dict[str, float]:
    out = {}
    for item in filter(None, (s.strip() for s in text.split(","))):
        name, _, value = item.partition("=")
        out[name] = float(value)
        if name not in FAULTS or not 0.0 <= out[name] <= 1.0:
            raise SystemExit(f"--faults: {item!r}: expected NAME=P with NAME in {', '.join(FAULTS)} and P in [0, 1]")
    return out


def serve(args: argparse.Namespace, position_source: PositionSource | None = None) -> int:
    """Serve with the options of ``parser()`` until shutdown (see the module docstring); ``position_source``: the
    SMR the emulator measures (mm, tracker frame; a caller's simulated cell), else a fixed point."""
    with EmsconEmulator(position_source, port=args.port, seed=args.seed, initialised=args.initialised,
                        meas_time_scale=args.meas_time_scale, late_s=args.late_s,
                        fault_probabilities=_fault_probabilities(args.faults)) as emulator:
        if args.print_port:
            print(emulator.port, flush=True)
        print(f"emScon emulator on {HOST}:{emulator.port}", file=sys.stderr, flush=True)
        wait_for_shutdown(watch_stdin=not args.ignore_stdin)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    return serve(parser().parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
