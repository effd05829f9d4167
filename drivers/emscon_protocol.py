"""Leica emScon binary protocol (TCP port 700): constants, packet layouts and framing, without I/O.

Written from the public C header ``ES_C_API_Def.h``: little-endian C structs packed to 4 bytes, ``long`` and enum
fields 4 bytes. Every packet starts with ``PacketHeaderT{long lPacketSize; ES_DataType type}`` (``lPacketSize`` counts
the whole packet). A command is ``BasicCommandCT{header, ES_Command command}`` + parameters; its reply
``BasicCommandRT{header, command, ES_ResultStatus status}`` + results. ``StartMeasurement`` is answered by a command
reply and then a separate ``SingleMeasResultT`` (type 2) or, in extended statistic mode, ``SingleMeasResult2T``
(type 9, with covariances). Unsolicited ``ErrorResponseT`` (type 1) and ``SystemStatusChangeT`` (type 8) packets may
arrive at any time.

Shared by the driver (``drivers.emscon``) and the emulator (``drivers.emulators.emscon_server``): one owner of the
byte layout. Only the subset of the header that the campaign needs is defined here.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

DEFAULT_PORT = 700
MAX_PACKET_BYTES = 65536

# ES_DataType
DT_COMMAND, DT_ERROR, DT_SINGLE_MEAS, DT_REFLECTOR_POS, DT_STATUS_CHANGE, DT_SINGLE_MEAS2 = 0, 1, 2, 7, 8, 9
KNOWN_TYPES = frozenset(range(0, 12))

# ES_Command (subset)
C_GET_SYSTEM_STATUS = 1
C_SET_UNITS = 5
C_INITIALIZE = 7
C_SET_ENVIRONMENT_PARAMS = 20
C_GET_ENVIRONMENT_PARAMS = 21
C_SET_MEASUREMENT_MODE = 24
C_SET_COORDINATE_SYSTEM_TYPE = 26
C_SET_STATIONARY_MODE_PARAMS = 28
C_SET_REFLECTOR = 40
C_GET_REFLECTOR = 41
C_GET_REFLECTORS = 42
C_SET_SYSTEM_SETTINGS = 47
C_GET_SYSTEM_SETTINGS = 48
C_START_MEASUREMENT = 49
C_STOP_MEASUREMENT = 52
C_GO_POSITION = 55
C_FIND_REFLECTOR = 63
C_SET_STATISTIC_MODE = 80
C_CLEAR_COMMAND_QUEUE = 130

# ES_ResultStatus (subset); ES_API_ERROR_OFFSET = 10000
RS_ALL_OK = 0
RS_SERVER_BUSY = 1
RS_NOT_IMPLEMENTED = 2
RS_WRONG_PARAMETER = 3
RS_NO_WEATHER_MONITOR = 27
RS_TRACKER_NOT_INITIALIZED = 39
RS_METEO_DATA_OUT_OF_RANGE = 57
RS_NO_TEMPERATURE_FROM_WM = 94
RS_MEASUREMENT_STATUS_NOT_READY = 10004
RS_NO_STATIONARY_RESULT = 10009
RS_SENSOR_NOT_LEVELED = 10010
RS_MULTI_CONNECTIONS_NOT_ALLOWED = 10011
RS_SENSOR_NOT_WARMED_UP = 10012
RS_SENSOR_NOT_STABLE = 10013
RS_SYSTEM_NOT_READY_FOR_MEASUREMENT = 10014
RS_COMMUNICATION_WITH_SENSOR_FAILED = 10015

STATUS_NAMES = {
    RS_ALL_OK: "AllOK", RS_SERVER_BUSY: "ServerBusy", RS_NOT_IMPLEMENTED: "NotImplemented",
    RS_WRONG_PARAMETER: "WrongParameter", RS_NO_WEATHER_MONITOR: "NoWeathermonitorFound",
    RS_TRACKER_NOT_INITIALIZED: "TrackerNotInitialized", RS_METEO_DATA_OUT_OF_RANGE: "MeteoDataOutOfRange",
    RS_NO_TEMPERATURE_FROM_WM: "NoTemperatureFromWM", RS_MEASUREMENT_STATUS_NOT_READY: "MeasurementStatusNotReady",
    RS_NO_STATIONARY_RESULT: "NoStationaryResult", RS_SENSOR_NOT_LEVELED: "SensorNotLeveled",
    RS_MULTI_CONNECTIONS_NOT_ALLOWED: "MultiConnectionsNotAllowed", RS_SENSOR_NOT_WARMED_UP: "SensorNotWarmedUp",
    RS_SENSOR_NOT_STABLE: "SensorNotStable", RS_SYSTEM_NOT_READY_FOR_MEASUREMENT: "SystemNotReadyForMeasurement",
    RS_COMMUNICATION_WITH_SENSOR_FAILED: "CommunicationWithSensorFailed",
}

# units, modes, settings
LU_MILLIMETER, AU_DEGREE, TU_CELSIUS, PU_MBAR, HU_RH = 1, 1, 0, 0, 0
CS_RHR = 0
MM_STATIONARY = 0
TPS_INITIALIZED = 5
WMS_NOT_CONNECTED, WMS_READ_ONLY, WMS_READ_AND_CALCULATE = 0, 1, 2
SM_STANDARD, SM_EXTENDED = 0, 1
SSC_MEAS_STATUS_NOT_READY, SSC_MEAS_STATUS_READY = 25, 27
TARGET_TYPES = {0: "Unknown", 1: "CornerCube", 2: "CatsEye", 3: "GlassPrism", 4: "RFIPrism", 5: "RRR15",
                6: "RRR05", 7: "BRR15", 8: "BRR05", 9: "TBR05", 10: "AutoCollMirror", 11: "RRR0875"}

# struct layouts ('<': little endian, no padding == pack(4) for these 4- and 8-byte fields)
HEADER = struct.Struct("<iI")                 # lPacketSize, type
COMMAND_CT = struct.Struct("<iII")            # header + command
COMMAND_RT = struct.Struct("<iIIi")           # header + command + status
ERROR_RESPONSE = struct.Struct("<iIIi")       # header + command + status
STATUS_CHANGE = struct.Struct("<iIi")         # header + systemStatusChange
RETURN_DATA = struct.Struct("<iIi")           # header + status

# parameters after BasicCommandCT / results after BasicCommandRT, per command
PARAMS = {
    C_SET_UNITS: struct.Struct("<5i"),                  # length, angle, temperature, pressure, humidity units
    C_SET_ENVIRONMENT_PARAMS: struct.Struct("<3d"),     # dTemperature, dPressure, dHumidity
    C_SET_MEASUREMENT_MODE: struct.Struct("<i"),        # ES_MeasMode
    C_SET_COORDINATE_SYSTEM_TYPE: struct.Struct("<i"),  # ES_CoordinateSystemType
    C_SET_STATIONARY_MODE_PARAMS: struct.Struct("<ii"),  # lMeasTime (ms), bUseADM
    C_SET_REFLECTOR: struct.Struct("<i"),               # iInternalReflectorId
    C_SET_SYSTEM_SETTINGS: struct.Struct("<9i"),        # SystemSettingsDataT
    C_GO_POSITION: struct.Struct("<3di"),               # dVal1..3, bUseADM
    C_FIND_REFLECTOR: struct.Struct("<d"),              # dAproxDistance
    C_SET_STATISTIC_MODE: struct.Struct("<ii"),         # stationary, continuous ES_StatisticMode
    C_CLEAR_COMMAND_QUEUE: struct.Struct("<i"),         # ES_ClearCommandQueueType
}
RESULTS = {
    # lastResultStatus, trackerProcessorStatus, laserStatus, admStatus, version major/minor/build,
    # weatherMonitorStatus, lFlagsValue, lTrackerSerialNumber
    C_GET_SYSTEM_STATUS: struct.Struct("<10i"),
    C_GET_ENVIRONMENT_PARAMS: struct.Struct("<3d"),
    C_GET_SYSTEM_SETTINGS: struct.Struct("<9i"),
    C_GET_REFLECTOR: struct.Struct("<i"),
    C_GET_REFLECTORS: struct.Struct("<iiid64s"),        # total, id, ES_TargetType, dSurfaceOffset, name (UTF-16LE)
}
SINGLE_MEAS = struct.Struct("<iIi" "ii" "17d")          # SingleMeasResultT, 156 bytes
SINGLE_MEAS2 = struct.Struct("<iIi" "ii" "23d")         # SingleMeasResult2T, 204 bytes
REFLECTOR_POS = struct.Struct("<iIi" "3d")


class FramingError(ValueError):
    """The byte stream cannot be a packet sequence (bad size or type): the connection is out of step."""


@dataclass(frozen=True)
class CommandReply:
    """``BasicCommandRT`` + ``payload`` (the command's result fields, unparsed)."""
    command: int
    status: int
    payload: bytes


@dataclass(frozen=True)
class ErrorPacket:
    """Unsolicited ``ErrorResponseT``: the command it concerns and the status."""
    command: int
    status: int


@dataclass(frozen=True)
class StatusChange:
    code: int


@dataclass(frozen=True)
class MeasResult:
    """``SingleMeasResultT``/``SingleMeasResult2T`` in the units set: values (dVal1..3), std devs (dStd1..3),
    covariances (12, 13, 23; zero for the type-2 packet) and the temperature, pressure, humidity used."""
    status: int
    meas_mode: int
    values: tuple[float, float, float]
    std: tuple[float, float, float]
    std_total: float
    covar: tuple[float, float, float]
    environment: tuple[float, float, float]
    extended: bool


@dataclass(frozen=True)
class OtherPacket:
    type: int
    data: bytes


Packet = CommandReply | ErrorPacket | StatusChange | MeasResult | OtherPacket


def status_name(status: int) -> str:
    return f"{STATUS_NAMES.get(status, 'status')} ({status})"


def encode_command(command: int, *params: float) -> bytes:
    """``BasicCommandCT`` for ``command`` with its parameters packed by ``PARAMS[command]``."""
    body = PARAMS[command].pack(*params) if command in PARAMS else b""
    return COMMAND_CT.pack(COMMAND_CT.size + len(body), DT_COMMAND, command) + body


def decode_command(data: bytes) -> tuple[int, tuple]:
    """(command, parameters) of a command packet (emulator side); ``FramingError`` if the size is wrong."""
    size, _, command = COMMAND_CT.unpack_from(data)
    fmt = PARAMS.get(command)
    expected = COMMAND_CT.size + (fmt.size if fmt else 0)
    if fmt is not None and len(data) != expected:
        raise FramingError(f"command {command}: {len(data)} bytes, expected {expected}")
    return command, (fmt.unpack_from(data, COMMAND_CT.size) if fmt else ())


def encode_reply(command: int, status: int, *results) -> bytes:
    """``BasicCommandRT`` + results packed by ``RESULTS[command]`` (none when the status is not AllOK)."""
    body = RESULTS[command].pack(*results) if results else b""
    return COMMAND_RT.pack(COMMAND_RT.size + len(body), DT_COMMAND, command, status) + body


def encode_error(command: int, status: int) -> bytes:
    return ERROR_RESPONSE.pack(ERROR_RESPONSE.size, DT_ERROR, command, status)


def encode_status_change(code: int) -> bytes:
    return STATUS_CHANGE.pack(STATUS_CHANGE.size, DT_STATUS_CHANGE, code)


def encode_meas_result(values, std, covar, environment, *, extended: bool, status: int = RS_ALL_OK,
                       pointing=(0.0, 0.0, 0.0)) -> bytes:
    """``SingleMeasResult2T`` (extended) or ``SingleMeasResultT``; a-priori std devs repeat the std devs."""
    std_total = float(sum(s * s for s in std)) ** 0.5
    if extended:
        doubles = (*values, *std, std_total, *covar, *pointing, *std, std_total, *covar, *environment)
        return SINGLE_MEAS2.pack(SINGLE_MEAS2.size, DT_SINGLE_MEAS2, status, MM_STATIONARY, 0, *doubles)
    doubles = (*values, *std, std_total, *pointing, *std, std_total, *environment)
    return SINGLE_MEAS.pack(SINGLE_MEAS.size, DT_SINGLE_MEAS, status, MM_STATIONARY, 0, *doubles)


def decode_packet(data: bytes) -> Packet:
    """One whole packet (as cut by ``PacketReader``) -> its record; ``FramingError`` on a size mismatch."""
    size, ptype = HEADER.unpack_from(data)
    if ptype == DT_COMMAND:
        _need(data, COMMAND_RT.size, "command reply")
        _, _, command, status = COMMAND_RT.unpack_from(data)
        return CommandReply(command, status, bytes(data[COMMAND_RT.size:]))
    if ptype == DT_ERROR:
        _need(data, ERROR_RESPONSE.size, "error packet")
        _, _, command, status = ERROR_RESPONSE.unpack_from(data)
        return ErrorPacket(command, status)
    if ptype == DT_STATUS_CHANGE:
        _need(data, STATUS_CHANGE.size, "status change")
        return StatusChange(STATUS_CHANGE.unpack_from(data)[2])
    if ptype in (DT_SINGLE_MEAS, DT_SINGLE_MEAS2):
        extended = ptype == DT_SINGLE_MEAS2
        fmt = SINGLE_MEAS2 if extended else SINGLE_MEAS
        _need(data, fmt.size, "measurement result", exact=True)
        f = fmt.unpack_from(data)
        status, mode, d = f[2], f[3], f[5:]
        if extended:
            return MeasResult(status, mode, d[0:3], d[3:6], d[6], d[7:10], d[20:23], True)
        return MeasResult(status, mode, d[0:3], d[3:6], d[6], (0.0, 0.0, 0.0), d[14:17], False)
    return OtherPacket(ptype, bytes(data))


def _need(data: bytes, n: int, what: str, exact: bool = False) -> None:
    if len(data) < n or (exact and len(data) != n):
        raise FramingError(f"{what}: {len(data)} bytes, expected {'' if exact else 'at least '}{n}")


class PacketReader:
    """Cuts a byte stream into packets by ``lPacketSize``; ``FramingError`` when the stream is out of step."""

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> None:
        self._buf += data

    def clear(self) -> None:
        self._buf.clear()

    def next_packet(self) -> bytes | None:
        """The next whole packet, or ``None`` if more bytes are needed."""
        if len(self._buf) < HEADER.size:
            return None
        size, ptype = HEADER.unpack_from(self._buf)
        if not HEADER.size + 4 <= size <= MAX_PACKET_BYTES or ptype not in KNOWN_TYPES:
            head = bytes(self._buf[:16])
            self._buf.clear()
            raise FramingError(f"not an emScon packet (size {size}, type {ptype}): {head.hex()}")
        if len(self._buf) < size:
            return None
        packet = bytes(self._buf[:size])
        del self._buf[:size]
        return packet
