"""Shared test helpers for the driver tests: run a server's command line and read the port it prints."""
from __future__ import annotations

import select
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

REPO = Path(__file__).resolve().parents[2]


@contextmanager
def served_port(module: str, *args: str, wait_s: float = 10.0, python_flags: tuple[str, ...] = (),
                cwd: Path = REPO) -> Iterator[tuple[subprocess.Popen, int]]:
    """Run ``python [python_flags] -m module --port 0 --print-port *args`` in ``cwd``; yield (process, port). Killed
    at exit if still running."""
    proc = subprocess.Popen([sys.executable, *python_flags, "-m", module, "--port", "0", "--print-port", *args],
                            cwd=cwd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        assert select.select([proc.stdout], [], [], wait_s)[0], f"{module} did not print its port"
        yield proc, int(proc.stdout.readline())
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
        proc.stdout.close()
        proc.stderr.close()
