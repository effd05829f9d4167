"""Client sessions of the UR controller emulator: RTDE, dashboard, script and control connections."""
from __future__ import annotations

import re
import select
import socket
import struct
import threading
import time

from . import rtde_protocol as proto
from .tcp import close_quietly


# --------------------------------------------------------------------------------------------- sessions

class Session(threading.Thread):
    """One client connection; subclasses implement ``serve``. Closing the socket ends the thread."""
    service = "?"

    def __init__(self, emulator: "Emulator", sock: socket.socket) -> None:
        super().__init__(daemon=True, name=f"{self.service}-session")
        self.emulator, self.sock = emulator, sock
        self.controller = emulator.controller
        self.send_lock = threading.Lock()       # packets from other threads (text messages) must not interleave

    def send(self, data: bytes) -> None:
        with self.send_lock:
            self.sock.sendall(data)

    def run(self) -> None:
        try:
            self.serve()
        except (OSError, ValueError, struct.error) as exc:
            self.emulator.debug(f"{self.service}: {type(exc).__name__}: {exc}")
        finally:
            self.emulator.forget(self)
            close_quietly(self.sock)

    def serve(self) -> None:
        raise NotImplementedError

    def close(self) -> None:
        try:
            self.sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        close_quietly(self.sock)


class RtdeSession(Session):
    """RTDE protocol server for one client: handshake, recipes, streaming outputs, receiving inputs."""
    service = "rtde"

    def serve(self) -> None:
        self.protocol = 1
        self.output: proto.Recipe | None = None
        self.inputs: dict[int, proto.Recipe] = {}
        self.period, self.streaming, self.next_send = 1 / 125, False, 0.0
        reader = proto.PacketReader()
        while True:
            timeout = max(0.0, self.next_send - time.monotonic()) if self.streaming else 0.2
            if select.select([self.sock], [], [], timeout)[0]:
                data = self.sock.recv(65536)
                if not data:
                    return
                if not self.emulator.frozen:
                    for ptype, payload in reader.feed(data):
                        self.handle(ptype, payload)
            self._stream()

    def _stream(self) -> None:
        now = time.monotonic()
        if not self.streaming or now < self.next_send or self.emulator.frozen or self.output is None:
            return
        self.send(proto.frame(proto.DATA_PACKAGE, self.output.pack(self.controller.outputs(self.output.names))))
        self.next_send = max(self.next_send + self.period, now + 0.2 * self.period)

    def reply(self, ptype: int, payload: bytes) -> None:
        self.send(proto.frame(ptype, payload))

    def handle(self, ptype: int, payload: bytes) -> None:
        handler = {proto.REQUEST_PROTOCOL_VERSION: self.on_version, proto.GET_URCONTROL_VERSION: self.on_urcontrol,
                   proto.CONTROL_PACKAGE_SETUP_OUTPUTS: self.on_outputs,
                   proto.CONTROL_PACKAGE_SETUP_INPUTS: self.on_inputs, proto.CONTROL_PACKAGE_START: self.on_start,
                   proto.CONTROL_PACKAGE_PAUSE: self.on_pause, proto.DATA_PACKAGE: self.on_data,
                   proto.TEXT_MESSAGE: self.on_text}.get(ptype)
        self.emulator.count_packet(chr(ptype) if 32 <= ptype < 127 else str(ptype))
        if handler is None:
            self.emulator.debug(f"rtde: unknown packet type {ptype}")
            return
        handler(payload)

    def on_version(self, payload: bytes) -> None:
        (version,) = struct.unpack_from(">H", payload)
        accepted = version in (1, 2)
        if accepted:
            self.protocol = version
        self.reply(proto.REQUEST_PROTOCOL_VERSION, struct.pack(">B", int(accepted)))

    def on_urcontrol(self, payload: bytes) -> None:
        self.reply(proto.GET_URCONTROL_VERSION, proto.version_reply(self.controller.version))

    def on_outputs(self, payload: bytes) -> None:
        freq, names = proto.parse_setup_outputs(payload, self.protocol)
        types = [proto.output_type(n) or "NOT_FOUND" for n in names]
        self.output = proto.make_recipe(1, names, types)
        rate = min(freq if freq > 0 else 125.0, self.emulator.max_rate_hz)
        self.period = 1.0 / rate
        self.reply(proto.CONTROL_PACKAGE_SETUP_OUTPUTS, proto.setup_reply(self.output))

    def on_inputs(self, payload: bytes) -> None:
        names = proto.parse_names(payload)
        types = [proto.input_type(n) or "NOT_FOUND" for n in names]
        types = ["IN_USE" if t != "NOT_FOUND" and self.emulator.in_use(self, n) else t for n, t in zip(names, types)]
        recipe_id = len(self.inputs) + 1 if all(t not in ("NOT_FOUND", "IN_USE") for t in types) else 0
        recipe = proto.make_recipe(recipe_id, names, types)
        if recipe_id:
            self.inputs[recipe_id] = recipe
        self.reply(proto.CONTROL_PACKAGE_SETUP_INPUTS, proto.setup_reply(recipe))

    def input_names(self) -> set[str]:
        return {n for r in self.inputs.values() for n in r.names}

    def on_start(self, payload: bytes) -> None:
        ok = self.output is not None and self.output.valid
        self.reply(proto.CONTROL_PACKAGE_START, struct.pack(">B", int(ok)))
        self.streaming, self.next_send = ok, time.monotonic()

    def on_pause(self, payload: bytes) -> None:
        self.streaming = False
        self.reply(proto.CONTROL_PACKAGE_PAUSE, struct.pack(">B", 1))

    def on_data(self, payload: bytes) -> None:
        recipe = self.inputs.get(payload[0]) if payload else None
        if recipe is None:
            self.emulator.debug(f"rtde: data package for unknown input recipe {payload[:1].hex()}")
            return
        self.controller.write_inputs(recipe.unpack(payload[1:]))

    def on_text(self, payload: bytes) -> None:
        self.emulator.debug("rtde: text message from client: %s (%s, level %d)" % proto.parse_text_message(payload))

    def send_text(self, message: str, level: int = 3) -> None:
        self.reply(proto.TEXT_MESSAGE, proto.text_message(message, "emulator", level))


class DashboardSession(Session):
    """Dashboard server (29999): one reply line per command line."""
    service = "dashboard"

    def serve(self) -> None:
        self.sock.sendall(b"Connected: Universal Robots Dashboard Server\n")
        for line in _recv_lines(self.sock):
            if self.emulator.frozen:
                continue
            answer = self.emulator.dashboard_reply(line)
            self.sock.sendall(answer.encode() + b"\n")
            if answer == "Disconnected":
                return


def _recv_lines(sock: socket.socket):
    """Yield the stripped text lines a client sends until it closes the connection."""
    buf = b""
    while True:
        data = sock.recv(4096)
        if not data:
            return
        buf += data
        while b"\n" in buf:
            line, buf = buf.split(b"\n", 1)
            yield line.decode("utf-8", "replace").strip()


class ScriptSession(Session):
    """Primary/secondary/real-time interface: accepts URScript, never replies."""
    service = "script"
    PROGRAM = re.compile(r"^(?:def|sec)\s+(\w+)\s*\(\s*\)\s*:\s*$(.*?)^end\s*$", re.M | re.S)

    def serve(self) -> None:
        text = ""
        while True:
            data = self.sock.recv(65536)
            if not data:
                return
            text += data.decode("utf-8", "replace")
            programs = list(self.PROGRAM.finditer(text))
            for m in programs:
                self.emulator.debug(f"script port {self.sock.getsockname()[1]}: program {m.group(1)}")
                self.controller.start_program(m.group(1), m.group(0))
            text = self._unfinished(text[programs[-1].end():] if programs else text)

    @staticmethod
    def _unfinished(text: str) -> str:
        """Keep only a program that has started but not ended yet (single script lines are ignored)."""
        starts = list(re.finditer(r"^(?:def|sec)\s", text, re.M))
        return text[starts[-1].start():] if starts else ""


class ControlSession(Session):
    """Test back door: one command line in, one ``OK ...`` / ``ERR ...`` line out."""
    service = "control"

    def serve(self) -> None:
        for line in _recv_lines(self.sock):
            self.sock.sendall(self.emulator.control_reply(line).encode() + b"\n")
