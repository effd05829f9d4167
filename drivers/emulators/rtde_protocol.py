"""UR RTDE wire protocol (server side), pure functions: framing, recipes, variable types.

Everything on the wire is big-endian. A packet is ``uint16 size`` (header included) + ``uint8 type`` +
payload. Variable names map to wire types through the tables below; they follow the types the ur_rtde
library decodes with (it uses its own name -> type table, not the types the server answers), see
``docs/drivers_ur.md``.
"""
from __future__ import annotations

import re
import struct
from dataclasses import dataclass
from typing import Any, Iterator, Mapping, Sequence

DASHBOARD_PORT = 29999                    # the controller's fixed ports (ur_rtde cannot be pointed elsewhere)
SCRIPT_PORTS = (30001, 30002, 30003)
RTDE_PORT = 30004
FIXED_PORTS = (DASHBOARD_PORT, *SCRIPT_PORTS, RTDE_PORT)

HEADER = struct.Struct(">HB")

# packet types
REQUEST_PROTOCOL_VERSION = ord("V")
GET_URCONTROL_VERSION = ord("v")
TEXT_MESSAGE = ord("M")
DATA_PACKAGE = ord("U")
CONTROL_PACKAGE_SETUP_OUTPUTS = ord("O")
CONTROL_PACKAGE_SETUP_INPUTS = ord("I")
CONTROL_PACKAGE_START = ord("S")
CONTROL_PACKAGE_PAUSE = ord("P")

STRUCT_CODES = {"BOOL": "?", "UINT8": "B", "UINT32": "I", "UINT64": "Q", "INT32": "i", "DOUBLE": "d",
                "VECTOR3D": "3d", "VECTOR6D": "6d", "VECTOR6INT32": "6i", "VECTOR6UINT32": "6I"}
VECTOR_SIZES = {"VECTOR3D": 3, "VECTOR6D": 6, "VECTOR6INT32": 6, "VECTOR6UINT32": 6}

_V6D = ("target_q target_qd target_qdd target_current target_moment actual_q actual_qd actual_current "
        "joint_control_output actual_TCP_pose actual_TCP_speed actual_TCP_force target_TCP_pose target_TCP_speed "
        "joint_temperatures actual_joint_voltage ft_raw_wrench payload_inertia tcp_offset "
        "actual_current_window actual_current_as_torque target_current_as_torque").split()
_DOUBLE = ("timestamp actual_execution_time speed_scaling target_speed_fraction actual_momentum actual_main_voltage "
           "actual_robot_voltage actual_robot_current standard_analog_input0 standard_analog_input1 "
           "standard_analog_output0 standard_analog_output1 io_current tool_analog_input0 tool_analog_input1 "
           "tool_output_current tool_temperature payload euromap67_24V_voltage euromap67_24V_current").split()
_UINT32 = ("runtime_state robot_status_bits safety_status_bits analog_io_types tool_analog_input_types tool_mode "
           "output_bit_registers0_to_31 output_bit_registers32_to_63 input_bit_registers0_to_31 "
           "input_bit_registers32_to_63 script_control_line euromap67_input_bits euromap67_output_bits").split()
_INT32 = "robot_mode safety_mode safety_status tool_output_voltage".split()
_UINT64 = "actual_digital_input_bits actual_digital_output_bits actual_configurable_digital_input_bits".split()
_V3D = "actual_tool_accelerometer payload_cog elbow_position elbow_velocity".split()

OUTPUT_TYPES: dict[str, str] = {**{n: "VECTOR6D" for n in _V6D}, **{n: "DOUBLE" for n in _DOUBLE},
                                **{n: "UINT32" for n in _UINT32}, **{n: "INT32" for n in _INT32},
                                **{n: "UINT64" for n in _UINT64}, **{n: "VECTOR3D" for n in _V3D},
                                "joint_mode": "VECTOR6INT32", "tool_accelerometer_values": "VECTOR3D"}

INPUT_TYPES: dict[str, str] = {
    "speed_slider_mask": "UINT32", "speed_slider_fraction": "DOUBLE",
    "standard_digital_output_mask": "UINT8", "standard_digital_output": "UINT8",
    "configurable_digital_output_mask": "UINT8", "configurable_digital_output": "UINT8",
    "tool_digital_output_mask": "UINT8", "tool_digital_output": "UINT8",
    "standard_analog_output_mask": "UINT8", "standard_analog_output_type": "UINT8",
    "standard_analog_output_0": "DOUBLE", "standard_analog_output_1": "DOUBLE",
    "input_bit_registers0_to_31": "UINT32", "input_bit_registers32_to_63": "UINT32",
    "external_force_torque": "VECTOR6D",
}

_REGISTER = re.compile(r"^(input|output)_(int|double|bit)_register_(\d+)$")
_REGISTER_TYPES = {"int": "INT32", "double": "DOUBLE", "bit": "BOOL"}
_REGISTER_RANGE = {"int": 48, "double": 48, "bit": 128}


def register_type(name: str) -> str | None:
    """Wire type of ``{input,output}_{int,double,bit}_register_N`` (N in the controller's range), else None."""
    m = _REGISTER.match(name)
    if not m or int(m.group(3)) >= _REGISTER_RANGE[m.group(2)] or (m.group(2) == "bit" and int(m.group(3)) < 64):
        return None
    return _REGISTER_TYPES[m.group(2)]


def output_type(name: str) -> str | None:
    """Wire type of an output (controller -> client) variable, None if unknown (answered NOT_FOUND)."""
    return OUTPUT_TYPES.get(name) or INPUT_TYPES.get(name) or register_type(name)


def input_type(name: str) -> str | None:
    """Wire type of an input (client -> controller) variable; only ``input_*`` registers are writable."""
    if name in INPUT_TYPES:
        return INPUT_TYPES[name]
    return register_type(name) if name.startswith("input_") else None


def frame(ptype: int, payload: bytes = b"") -> bytes:
    """One packet: header (size incl. header, type) + payload."""
    return HEADER.pack(HEADER.size + len(payload), ptype) + payload


class PacketReader:
    """Incremental framer: ``feed`` bytes, iterate complete ``(type, payload)`` packets."""

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> Iterator[tuple[int, bytes]]:
        self._buf += data
        while len(self._buf) >= HEADER.size:
            size, ptype = HEADER.unpack_from(self._buf)
            if size < HEADER.size:
                raise ValueError(f"bad RTDE packet size {size}")
            if len(self._buf) < size:
                return
            payload = bytes(self._buf[HEADER.size:size])
            del self._buf[:size]
            yield ptype, payload


@dataclass(frozen=True)
class Recipe:
    """An output or input recipe: variable names, their wire types and the packed layout."""
    recipe_id: int
    names: tuple[str, ...]
    types: tuple[str, ...]

    @property
    def valid(self) -> bool:
        return all(t not in ("NOT_FOUND", "IN_USE") for t in self.types)

    @property
    def struct(self) -> struct.Struct:
        return struct.Struct(">" + "".join(STRUCT_CODES[t] for t in self.types))

    def pack(self, values: Mapping[str, Any]) -> bytes:
        """DATA_PACKAGE payload: recipe id + values in recipe order (missing names -> zeros)."""
        flat: list[Any] = []
        for name, typ in zip(self.names, self.types):
            flat.extend(_flatten(values.get(name), typ))
        return struct.pack(">B", self.recipe_id) + self.struct.pack(*flat)

    def unpack(self, body: bytes) -> dict[str, Any]:
        """Values of a DATA_PACKAGE body (after the recipe id byte); a short body decodes a prefix only."""
        out: dict[str, Any] = {}
        offset = 0
        for name, typ in zip(self.names, self.types):
            item = struct.Struct(">" + STRUCT_CODES[typ])
            if offset + item.size > len(body):
                break
            vals = item.unpack_from(body, offset)
            offset += item.size
            out[name] = vals if typ in VECTOR_SIZES else vals[0]
        return out


def _flatten(value: Any, typ: str) -> list[Any]:
    """Struct arguments of one value (None -> zeros of the type)."""
    conv: Any = float if typ in ("DOUBLE", "VECTOR3D", "VECTOR6D") else (bool if typ == "BOOL" else int)
    n = VECTOR_SIZES.get(typ)
    if n is None:
        return [conv(0 if value is None else value)]
    return [conv(v) for v in ([0] * n if value is None else value)]


def make_recipe(recipe_id: int, names: Sequence[str], types: Sequence[str]) -> Recipe:
    return Recipe(recipe_id, tuple(names), tuple(types))


def parse_names(text: bytes) -> list[str]:
    """Comma-separated variable names; ur_rtde appends a trailing comma, which is dropped."""
    return [n.strip() for n in text.decode("ascii", "replace").split(",") if n.strip()]


def parse_setup_outputs(payload: bytes, protocol_version: int) -> tuple[float, list[str]]:
    """CONTROL_PACKAGE_SETUP_OUTPUTS payload -> (frequency Hz, names); v1 has no frequency (125 Hz)."""
    if protocol_version >= 2:
        (freq,) = struct.unpack_from(">d", payload)
        return freq, parse_names(payload[8:])
    return 125.0, parse_names(payload)


def setup_reply(recipe: Recipe) -> bytes:
    """Reply payload to a setup request: recipe id + comma-separated type names."""
    return struct.pack(">B", recipe.recipe_id) + ",".join(recipe.types).encode("ascii")


def version_reply(version: Sequence[int]) -> bytes:
    """GET_URCONTROL_VERSION reply: major, minor, bugfix, build as uint32."""
    return struct.pack(">IIII", *version)


def text_message(message: str, source: str = "emulator", level: int = 3) -> bytes:
    """TEXT_MESSAGE payload (protocol v2): len+message, len+source, level (0 exception .. 3 info)."""
    m, s = message.encode()[:255], source.encode()[:255]
    return struct.pack(">B", len(m)) + m + struct.pack(">B", len(s)) + s + struct.pack(">B", level)


def parse_text_message(payload: bytes) -> tuple[str, str, int]:
    """(message, source, level) of a protocol-v2 TEXT_MESSAGE payload."""
    n = payload[0]
    msg = payload[1:1 + n].decode("utf-8", "replace")
    k = payload[1 + n] if len(payload) > 1 + n else 0
    src = payload[2 + n:2 + n + k].decode("utf-8", "replace")
    level = payload[2 + n + k] if len(payload) > 2 + n + k else 3
    return msg, src, level
