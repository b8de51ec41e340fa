"""The ESP8266 link: a TCP server the robots connect to (no ROS).

Robots are TCP clients; the server tells them apart by the last octet of
the peer's IPv4 address (``ip_octet`` in the robot list). A new connection
from a known octet replaces the robot's previous one at any time
(reconnects); a connection from an unknown octet is logged and closed. A
configured robot that is not connected is reported, never fatal.

Sending is done from the control loop's thread with :meth:`PwmServer.send`;
a background thread accepts connections and reads whatever the robots send
(the firmware sends nothing we use: lines are logged and dropped). Only the
newest PWM line matters, so a robot whose socket buffer is full gets its
pending data replaced by the newest line (after finishing a partly sent
one), and one that takes nothing for ``send_stall_timeout`` seconds is
disconnected.
"""

import logging
import selectors
import socket
import threading
import time
from dataclasses import dataclass
from typing import Optional

from puzzlebot_driver.protocol import ProtocolError, format_pwm, ip_last_octet

_LOG = logging.getLogger("puzzlebot_driver.link")
_READ_SIZE = 4096
_MAX_LINE = 256          # bytes; longer input without a newline counts as one garbage line


class LinkError(RuntimeError):
    """The server cannot start (e.g. the port is in use)."""


@dataclass
class LinkInfo:
    """Link state of one robot (for diagnostics)."""

    connected: bool = False
    address: str = ""
    connects: int = 0              # connections accepted so far
    last_change: float = 0.0       # monotonic time of the last connect/disconnect
    lines_sent: int = 0
    lines_received: int = 0        # lines the robot sent us (ignored)
    last_error: str = ""


class _Conn:
    def __init__(self, sock, address):
        self.sock = sock
        self.address = address
        self.pending = b""           # unsent bytes (the tail of a partly sent line + newest line)
        self.partial = 0             # how many leading bytes of pending belong to a partly sent line
        self.stalled_since = None    # monotonic time since which nothing could be sent
        self.inbuf = b""


class PwmServer:
    """TCP server that sends PWM lines to robots identified by IP last octet."""

    def __init__(self, robots, host="0.0.0.0", port=8080, params=None, log=None):
        """``robots``: {ip_octet: robot name}; ``params``: DriverParams (keepalive, stall
        timeout) or None for defaults; ``log(level, text)`` with level in
        "info", "warn", "error" (default: the logging module)."""
        from puzzlebot_driver.params import DriverParams

        self.names = dict(robots)
        self.host, self._port = host, port
        self.params = params or DriverParams()
        self._log = log or (lambda level, text: _LOG.log(
            {"info": logging.INFO, "warn": logging.WARNING, "error": logging.ERROR}[level], text))
        self._lock = threading.Lock()
        self._conns = {}                                   # name -> _Conn
        self.info = {name: LinkInfo() for name in self.names.values()}
        self._listener = None
        self._selector = None
        self._thread = None
        self._stop = threading.Event()
        self.rejected_connections = 0

    # ----------------------------------------------------------------- set-up
    @property
    def port(self):
        """The port actually listened on (useful with port 0 in tests)."""
        return self._listener.getsockname()[1] if self._listener else self._port

    def start(self):
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((self.host, self._port))
        except OSError as e:
            sock.close()
            raise LinkError("cannot listen on %s:%d: %s" % (self.host, self._port, e.strerror or e)) from None
        sock.listen(16)
        sock.setblocking(False)
        self._listener = sock
        self._selector = selectors.DefaultSelector()
        self._selector.register(sock, selectors.EVENT_READ, None)
        self._thread = threading.Thread(target=self._run, name="pwm_server", daemon=True)
        self._thread.start()
        return self

    def stop(self, zero=True):
        """Send PWM 0 to every connected robot (if ``zero``), then close everything."""
        if zero:
            for name in list(self.names.values()):
                self.send(name, 0, 0, flush_timeout=0.2)
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        with self._lock:
            for name in list(self._conns):
                self._close(name, "server stopped", log=False)
        if self._listener is not None:
            self._listener.close()
        if self._selector is not None:
            self._selector.close()

    # ------------------------------------------------------------------ state
    def connected(self, name):
        with self._lock:
            return name in self._conns

    def connected_names(self):
        with self._lock:
            return sorted(self._conns)

    # ---------------------------------------------------------------- sending
    def send(self, name, left, right, flush_timeout=0.0):
        """Queue the PWM line for ``name`` and send what the socket takes.

        Returns True if the whole line left for the robot, False if it is not
        connected or the line is (partly) pending. ``flush_timeout`` > 0 waits
        that long for pending data to leave (used for the final zero).
        """
        line = format_pwm(left, right)
        with self._lock:
            conn = self._conns.get(name)
            if conn is None:
                return False
            # Keep the unsent tail of a partly sent line (framing), drop older whole lines.
            conn.pending = conn.pending[:conn.partial] + line
            ok = self._flush(name, conn)
            if ok:
                self.info[name].lines_sent += 1
        deadline = time.monotonic() + flush_timeout
        while not ok and flush_timeout > 0 and time.monotonic() < deadline:
            time.sleep(0.005)
            with self._lock:
                conn = self._conns.get(name)
                if conn is None:
                    return False
                ok = self._flush(name, conn)
        return ok

    def _flush(self, name, conn):
        """Send pending bytes (lock held); True when nothing is pending."""
        try:
            n = conn.sock.send(conn.pending)
        except (BlockingIOError, InterruptedError):
            n = 0
        except OSError as e:
            self._close(name, "send failed: %s" % (e.strerror or e))
            return False
        line_len = len(format_pwm(0, 0))
        conn.pending = conn.pending[n:]
        if not conn.pending:
            conn.partial, conn.stalled_since = 0, None
            return True
        # Bytes left of the line currently on the wire (the rest are whole lines).
        conn.partial = len(conn.pending) % line_len
        now = time.monotonic()
        if n > 0 or conn.stalled_since is None:
            conn.stalled_since = now if n == 0 else None
        if conn.stalled_since is not None and now - conn.stalled_since > self.params.send_stall_timeout:
            self._close(name, "link stalled: nothing sent for %.1f s" % (now - conn.stalled_since))
        return False

    # --------------------------------------------------------- server thread
    def _run(self):
        while not self._stop.is_set():
            try:
                events = self._selector.select(timeout=0.1)
            except (OSError, ValueError):
                if self._stop.is_set():
                    return
                raise
            for key, _ in events:
                if key.data is None:
                    self._accept()
                else:
                    self._read(key.data)

    def _configure(self, sock):
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)   # a 10-byte line goes out at once
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
        p = self.params
        for opt, value in (("TCP_KEEPIDLE", p.keepalive_idle), ("TCP_KEEPINTVL", p.keepalive_interval),
                           ("TCP_KEEPCNT", p.keepalive_count)):
            if hasattr(socket, opt):
                sock.setsockopt(socket.IPPROTO_TCP, getattr(socket, opt), max(1, int(round(value))))
        if hasattr(socket, "TCP_USER_TIMEOUT"):
            # A robot that vanished while we send (power off, out of range) never ACKs; without this
            # the kernel retransmits for many minutes and the link would look up all that time.
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_USER_TIMEOUT, int(1000 * p.ack_timeout))
        sock.setblocking(False)

    def _accept(self):
        try:
            sock, (addr, _port) = self._listener.accept()
        except (BlockingIOError, InterruptedError):
            return
        except OSError as e:
            self._log("warn", "accept failed: %s" % (e.strerror or e))
            return
        try:
            name = self.names.get(ip_last_octet(addr))
        except ProtocolError:
            name = None
        if name is None:
            self.rejected_connections += 1
            self._log("warn", "connection from %s refused: its last IP octet names no robot of the "
                              "robot list (known octets: %s)"
                      % (addr, ", ".join(str(o) for o in sorted(self.names)) or "none"))
            sock.close()
            return
        self._configure(sock)
        conn = _Conn(sock, addr)
        with self._lock:
            old = self._conns.get(name)
            if old is not None:
                self._close(name, "replaced by a new connection from %s" % addr)
            self._conns[name] = conn
            info = self.info[name]
            info.connected, info.address, info.last_change = True, addr, time.monotonic()
            info.connects += 1
            self._selector.register(sock, selectors.EVENT_READ, name)
        self._log("info", "%s connected from %s (connection %d)" % (name, addr, info.connects))

    def _read(self, name):
        with self._lock:
            conn = self._conns.get(name)
        if conn is None:
            return
        try:
            data = conn.sock.recv(_READ_SIZE)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as e:
            with self._lock:
                if self._conns.get(name) is conn:
                    self._close(name, "receive failed: %s" % (e.strerror or e))
            return
        if not data:
            with self._lock:
                if self._conns.get(name) is conn:
                    self._close(name, "closed by the robot")
            return
        conn.inbuf += data
        lines = conn.inbuf.split(b"\n")
        conn.inbuf = lines.pop()
        if len(conn.inbuf) > _MAX_LINE:
            lines.append(conn.inbuf)
            conn.inbuf = b""
        for line in lines:
            self.info[name].lines_received += 1
            n = self.info[name].lines_received
            if n <= 3 or n % 100 == 0:
                self._log("warn", "%s sent %r (line %d from this robot; robots are not expected to send "
                                  "anything: ignored)" % (name, line[:64], n))

    def _close(self, name, why, log=True):
        """Drop ``name``'s connection (lock held)."""
        conn = self._conns.pop(name, None)
        if conn is None:
            return
        try:
            self._selector.unregister(conn.sock)
        except (KeyError, ValueError):
            pass
        try:
            conn.sock.close()
        except OSError:
            pass
        info = self.info[name]
        info.connected, info.last_change, info.last_error = False, time.monotonic(), why
        if log:
            self._log("warn", "%s disconnected (%s): the robot keeps its last PWM until it reconnects"
                      % (name, why))

    def link_info(self, name) -> Optional[LinkInfo]:
        with self._lock:
            info = self.info.get(name)
            return None if info is None else LinkInfo(**vars(info))
