"""Shared TCP plumbing for the emulators and the reference bridge: listening sockets, quiet closes and the
one-client-at-a-time server thread (``TcpServer``) that the tracker, emScon and bridge servers build on."""
from __future__ import annotations

import os
import select
import signal
import socket
import sys
import threading
from typing import Iterator


def listen(host: str, port: int, backlog: int = 16) -> socket.socket:
    """A listening TCP socket on ``host:port`` (``SO_REUSEADDR``; port 0 = ephemeral)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind((host, port))
    sock.listen(backlog)
    return sock


def close_quietly(sock: socket.socket | None) -> None:
    """Close ``sock``; ``None`` and errors are ignored."""
    if sock is None:
        return
    try:
        sock.close()
    except OSError:
        pass


def _watch_stdin(done: threading.Event) -> None:
    """Set ``done`` at end of file on stdin (raw reads: no buffered-reader lock held at interpreter exit)."""
    try:
        while os.read(sys.stdin.fileno(), 4096):
            pass
    except (OSError, ValueError):
        pass
    done.set()


def wait_for_shutdown(watch_stdin: bool = True) -> None:
    """Block a server's command line until SIGTERM, Ctrl-C or (``watch_stdin``) end of file on stdin."""
    done = threading.Event()
    if watch_stdin:
        threading.Thread(target=_watch_stdin, args=(done,), name="stdin-watch", daemon=True).start()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    try:
        while not done.wait(0.2):
            pass
    except KeyboardInterrupt:
        pass


class TcpServer:
    """One background thread that accepts TCP clients on ``host:port`` and serves them one at a time.

    Subclasses implement ``_serve_client(conn)`` (usually over ``_received(conn)`` or ``_lines(conn)``) and
    set ``thread_name``, ``label`` and ``poll_s`` (s between checks of the stop flag). ``port=0`` picks a free port (read
    ``.port`` after ``start()``); ``connections`` counts accepted clients. A context manager.
    """
    thread_name = "tcp-server"
    label = "TCP server"          # for messages
    poll_s = 0.05

    def __init__(self, host: str, port: int = 0) -> None:
        self.host, self._requested_port = host, port
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._listener: socket.socket | None = None
        self.port = 0
        self.connections = 0

    def start(self):
        """Bind, listen and start serving (idempotent); returns self."""
        if self._thread is not None:
            return self
        self._listener = listen(self.host, self._requested_port, backlog=1)
        self.port = self._listener.getsockname()[1]
        self._stop.clear()
        self._thread = threading.Thread(target=self._serve, name=f"{self.thread_name}-{self.port}", daemon=True)
        self._thread.start()
        return self

    def _join(self, timeout_s: float) -> bool:
        """Ask the thread to stop and join it; ``False`` if it is still alive after ``timeout_s`` s."""
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is None:
            return True
        thread.join(timeout_s)
        return not thread.is_alive()

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop serving, close all sockets and join the thread (within about ``poll_s``)."""
        if not self._join(timeout_s):
            raise RuntimeError(f"{self.label} thread did not stop within {timeout_s} s")

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _serve(self) -> None:
        listener = self._listener
        try:
            while not self._stop.is_set():
                if select.select([listener], [], [], self.poll_s)[0]:
                    conn, _ = listener.accept()
                    self.connections += 1
                    with conn:
                        self._serve_client(conn)
        finally:
            listener.close()

    def _serve_client(self, conn: socket.socket) -> None:
        raise NotImplementedError

    def _received(self, conn: socket.socket, bufsize: int = 4096) -> Iterator[bytes]:
        """The chunks a client sends, until stop, end of stream or a socket error."""
        while not self._stop.is_set():
            if not select.select([conn], [], [], self.poll_s)[0]:
                continue
            try:
                data = conn.recv(bufsize)
            except OSError:
                return
            if not data:
                return
            yield data

    def _lines(self, conn: socket.socket) -> Iterator[bytes]:
        """The ``\\n``-terminated lines a client sends (terminator removed), as ``_received``."""
        buf = b""
        for data in self._received(conn):
            buf += data
            while b"\n" in buf:
                line, buf = buf.split(b"\n", 1)
                yield line

    def _deliver(self, conn: socket.socket, data: bytes, delay_s: float = 0.0, disconnect: bool = False) -> bool:
        """Send one reply after ``delay_s`` s (cut short by ``stop()``); ``False`` when the connection must end."""
        if disconnect or (delay_s and self._stop.wait(delay_s)):
            return False
        try:
            if data:
                conn.sendall(data)
        except OSError:
            return False
        return True
