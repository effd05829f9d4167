"""Run the RTDE emulator (``python -m drivers.emulators.rtde_server``) as a subprocess for tests and demos."""
from __future__ import annotations

import json
import os
import random
import select
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from typing import Any, Sequence

from .tcp import listen
from .rtde_protocol import FIXED_PORTS

# --------------------------------------------------------------------------------------------- helper

@dataclass
class EmulatorProcess:
    """A running emulator subprocess: its ports, a back-door client, and ``stop()`` (always call it)."""
    host: str
    ports: dict[str, Any]
    process: subprocess.Popen
    log_path: str
    _stopped: bool = field(default=False, repr=False)

    def command(self, line: str, timeout_s: float = 2.0) -> str:
        """Send one back-door command; return the text after ``OK`` (raise RuntimeError on ``ERR``)."""
        with socket.create_connection((self.host, self.ports["control"]), timeout=timeout_s) as sock:
            sock.sendall(line.encode() + b"\n")
            reply = b""
            while not reply.endswith(b"\n"):
                chunk = sock.recv(65536)
                if not chunk:
                    break
                reply += chunk
        text = reply.decode().strip()
        if not text.startswith("OK"):
            raise RuntimeError(f"emulator {self.host}: {line!r} -> {text!r}")
        return text[3:]

    def state(self) -> dict[str, Any]:
        return json.loads(self.command("STATE"))

    def log(self) -> dict[str, Any]:
        return json.loads(self.command("LOG"))

    def stderr_tail(self, n: int = 20) -> str:
        try:
            with open(self.log_path, encoding="utf-8", errors="replace") as f:
                return "".join(f.readlines()[-n:])
        except OSError:
            return ""

    def stop(self, timeout_s: float = 3.0) -> None:
        """Ask the emulator to quit, then terminate / kill it; idempotent."""
        if self._stopped:
            return
        self._stopped = True
        if self.process.poll() is None:
            try:
                self.command("QUIT", timeout_s=0.5)
            except (OSError, RuntimeError):
                pass
        _reap(self.process, timeout_s)
        if self.process.stdout is not None:
            self.process.stdout.close()
        try:
            os.unlink(self.log_path)
        except OSError:
            pass

    def __enter__(self) -> "EmulatorProcess":
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def _reap(process: subprocess.Popen, timeout_s: float) -> None:
    for action in (None, process.terminate, process.kill):
        if action is not None and process.poll() is None:
            action()
        try:
            process.wait(timeout=timeout_s)
            return
        except subprocess.TimeoutExpired:
            continue


def free_loopback_host(attempts: int = 50) -> str:
    """A random 127.x.y.z on which all fixed UR ports are free (Linux routes all of 127/8 to lo)."""
    rng = random.Random()
    for _ in range(attempts):
        host = f"127.{rng.randint(1, 254)}.{rng.randint(0, 255)}.{rng.randint(1, 254)}"
        try:
            for sock in [listen(host, p) for p in FIXED_PORTS]:
                sock.close()
            return host
        except OSError:
            continue
    raise RuntimeError("no free loopback address for the UR emulator")


def start_emulator(host: str | None = None, extra_args: Sequence[str] = (), timeout_s: float = 10.0) -> EmulatorProcess:
    """Start the emulator as a subprocess on ``host`` (default: a free random loopback address)."""
    host = host or free_loopback_host()
    fd, log_path = tempfile.mkstemp(prefix="rtde_emulator_", suffix=".log")
    cmd = [sys.executable, "-m", "drivers.emulators.rtde_server", "--host", host, "--print-ports", *extra_args]
    with os.fdopen(fd, "w") as log:
        process = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=log, stdin=subprocess.DEVNULL)
    handle = EmulatorProcess(host, {}, process, log_path)
    try:
        handle.ports = _read_ports(process, timeout_s)
    except BaseException:
        tail = handle.stderr_tail()
        handle.stop()
        raise RuntimeError(f"UR emulator on {host} did not start: {tail.strip()[-500:]}") from None
    return handle


def _read_ports(process: subprocess.Popen, timeout_s: float) -> dict[str, Any]:
    assert process.stdout is not None
    deadline = time.monotonic() + timeout_s
    line = b""
    while not line.endswith(b"\n"):
        remaining = deadline - time.monotonic()
        if remaining <= 0 or not select.select([process.stdout], [], [], remaining)[0]:
            raise TimeoutError("no ports line")
        chunk = os.read(process.stdout.fileno(), 4096)
        if not chunk:
            raise EOFError("emulator exited")
        line += chunk
    return json.loads(line.decode())

