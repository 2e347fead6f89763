"""Byte sources of a GNSS receiver stream: serial port, TCP client, TCP server, recorded file.

Every source has the same small interface, ``read(max_bytes, timeout) -> bytes``, and owns
its reconnection: a failed open or a lost connection (unplugged USB receiver, closed socket,
missing file) is reported through ``notify(event, detail)`` and retried with exponential
backoff, and ``read`` returns ``b""`` meanwhile instead of raising, so a driver that polls it
never stops; :class:`SourceReader` reads one in a thread of its own instead, waiting for bytes
rather than polling.  Sources are selected by a URL (:func:`open_source`):

* ``serial:///dev/ttyACM0?baud=115200`` (pyserial; ``baud`` defaults to 115200)
* ``tcp://HOST:PORT``: connect to a receiver or an NTRIP-style caster that serves the stream
* ``tcp-listen://HOST:PORT``: listen (one client at a time); HOST defaults to 127.0.0.1, so
  the port is not exposed beyond the machine unless configured
* ``file:///path.ubx?pace=recorded|fast``: a recorded stream.  The bytes carry no time
  stamps of their own: pacing at the recorded rate needs the GNSS epochs decoded from them,
  so the reader of a file source releases decoded records through a :class:`Pacer`.

Events passed to ``notify``: ``connected``, ``connect failed``, ``lost``, ``client
connected``, ``client disconnected``, ``end of file``.
"""

from __future__ import annotations

import math
import select
import socket
import threading
import time
from typing import Callable
from urllib.parse import parse_qs, urlsplit

import serial

#: Events that are normal operation (the others are faults).
NORMAL_EVENTS = frozenset({"connected", "client connected", "client disconnected", "end of file"})


class ByteSource:
    """Base class: reconnection with exponential backoff around ``_open``/``_read``/``_close``.

    Parameters
    ----------
    name : str
        What the source reads, for messages.
    notify : callable(event, detail), optional
        Receives every connection event (see module docstring).
    clock : callable() -> float, optional
        Monotonic time [s]; injectable for tests.
    retry_initial_s, retry_max_s : float
        First wait after a failure and the cap of the doubling waits [s].
    """

    def __init__(self, name: str, notify: Callable[[str, str], None] | None = None,
                 clock: Callable[[], float] = time.monotonic, retry_initial_s: float = 0.5,
                 retry_max_s: float = 10.0):
        self.name = name
        self._notify = notify or (lambda event, detail: None)
        self._clock = clock
        self.retry_initial_s, self.retry_max_s = retry_initial_s, retry_max_s
        self._backoff = retry_initial_s
        self._next_attempt = -math.inf
        self.connected = False

    def read(self, max_bytes: int = 65536, timeout: float = 0.0) -> bytes:
        """Up to ``max_bytes`` bytes, waiting at most ``timeout`` s for the first one.

        Returns ``b""`` when nothing arrived, and at once while the source waits to reconnect.
        """
        if not self.connected:
            if self._clock() < self._next_attempt:
                return b""
            try:
                self._open()
            except OSError as err:
                self._failed("connect failed", err)
                return b""
            self.connected = True
            self._backoff = self.retry_initial_s
            self._notify("connected", self.name)
        try:
            return self._read(max_bytes, timeout)
        except OSError as err:  # pyserial's SerialException and socket errors are OSErrors
            self._failed("lost", err)
            return b""

    def reconnect_in_s(self) -> float:
        """Seconds until ``read`` tries to open the source again (0 when connected or due)."""
        return 0.0 if self.connected else max(0.0, self._next_attempt - self._clock())

    def close(self) -> None:
        """Release the device; a later ``read`` opens it again."""
        if self.connected:
            self._close()
            self.connected = False

    def _failed(self, event: str, err: Exception) -> None:
        self.close()
        # Doubling waits: a receiver that is being re-plugged is found within a second, a
        # port that is gone for good costs one attempt per retry_max_s.
        self._next_attempt = self._clock() + self._backoff
        self._notify(event, f"{self.name}: {err} (retry in {self._backoff:g} s)")
        self._backoff = min(2.0 * self._backoff, self.retry_max_s)

    def _open(self) -> None:
        raise NotImplementedError

    def _read(self, max_bytes: int, timeout: float) -> bytes:
        raise NotImplementedError

    def _close(self) -> None:
        raise NotImplementedError


class SerialSource(ByteSource):
    """A serial port (USB CDC or UART) through pyserial, 8N1, no flow control."""

    def __init__(self, port: str, baud: int = 115200, **kwargs):
        super().__init__(f"serial {port} at {baud} Bd", **kwargs)
        self.port, self.baud = port, baud
        self._serial: serial.Serial | None = None

    def _open(self) -> None:
        self._serial = serial.Serial(self.port, self.baud, timeout=0)

    def _read(self, max_bytes: int, timeout: float) -> bytes:
        # Wait for the first byte only, then take what is buffered: a fixed-size read would
        # wait for the whole timeout on a slow line.
        ready, _, _ = select.select([self._serial.fileno()], [], [], timeout)
        if not ready:
            return b""
        data = self._serial.read(max_bytes)
        if not data:
            # Readable but empty: the device is gone (a closed pty, an unplugged USB port).
            raise serial.SerialException("device reports data but returned none (disconnected)")
        return data

    def _close(self) -> None:
        try:
            self._serial.close()
        except OSError:
            pass  # closing a vanished device may fail; it is released either way
        self._serial = None


def _recv(sock: socket.socket, max_bytes: int, timeout: float) -> bytes:
    """Bytes from a connected stream socket; ConnectionError when the peer closed it."""
    ready, _, _ = select.select([sock], [], [], timeout)
    if not ready:
        return b""
    data = sock.recv(max_bytes)
    if not data:
        raise ConnectionError("peer closed the connection")
    return data


class TcpClientSource(ByteSource):
    """A TCP connection to a receiver or stream server."""

    def __init__(self, host: str, port: int, connect_timeout_s: float = 2.0, **kwargs):
        super().__init__(f"tcp {host}:{port}", **kwargs)
        self.address = (host, port)
        self.connect_timeout_s = connect_timeout_s
        self._sock: socket.socket | None = None

    def _open(self) -> None:
        self._sock = socket.create_connection(self.address, timeout=self.connect_timeout_s)

    def _read(self, max_bytes: int, timeout: float) -> bytes:
        return _recv(self._sock, max_bytes, timeout)

    def _close(self) -> None:
        self._sock.close()
        self._sock = None


class TcpServerSource(ByteSource):
    """Listens on a TCP port and reads the stream of one client at a time.

    A client that disconnects is reported and the next one accepted; a newer client does not
    displace a connected one (it waits in the listen backlog).
    """

    def __init__(self, host: str, port: int, **kwargs):
        super().__init__(f"tcp-listen {host}:{port}", **kwargs)
        self.address = (host, port)
        self._listener: socket.socket | None = None
        self._client: socket.socket | None = None

    @property
    def port(self) -> int:
        """The bound port (useful when 0 asked the system for a free one)."""
        return self._listener.getsockname()[1] if self._listener else self.address[1]

    def _open(self) -> None:
        listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            listener.bind(self.address)
            listener.listen(1)
        except OSError:
            listener.close()
            raise
        self._listener = listener

    def _read(self, max_bytes: int, timeout: float) -> bytes:
        if self._client is None:
            ready, _, _ = select.select([self._listener], [], [], timeout)
            if not ready:
                return b""
            self._client, peer = self._listener.accept()
            self._notify("client connected", f"{self.name}: {peer[0]}:{peer[1]}")
            timeout = 0.0
        try:
            return _recv(self._client, max_bytes, timeout)
        except OSError as err:  # the client went away: keep listening for the next one
            self._drop_client()
            self._notify("client disconnected", f"{self.name}: {err}")
            return b""

    def _drop_client(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None

    def _close(self) -> None:
        self._drop_client()
        self._listener.close()
        self._listener = None


class FileSource(ByteSource):
    """A recorded stream file, read once from start to end.

    ``pace`` is carried for the reader ("recorded" or "fast"); the bytes themselves are
    returned as fast as they are asked for.  At the end ``finished`` is set and
    ``end of file`` reported once.
    """

    def __init__(self, path: str, pace: str = "recorded", **kwargs):
        if pace not in ("recorded", "fast"):
            raise ValueError(f"file pace must be 'recorded' or 'fast', got {pace!r}")
        super().__init__(f"file {path}", **kwargs)
        self.path, self.pace = path, pace
        self._file = None
        self.offset = 0
        self.finished = False

    def _open(self) -> None:
        self._file = open(self.path, "rb")
        self._file.seek(self.offset)  # a re-opened file continues where it stopped

    def _read(self, max_bytes: int, timeout: float) -> bytes:
        if self.finished:
            return b""
        data = self._file.read(max_bytes)
        self.offset += len(data)
        if not data:
            self.finished = True
            self._notify("end of file", f"{self.name}: {self.offset} bytes")
        return data

    def _close(self) -> None:
        self._file.close()
        self._file = None


class Pacer:
    """Releases time-tagged items no earlier than their recorded spacing (replay in real time).

    The first item anchors stream time to the clock; an item of stream time ``t`` is due
    ``t - t_first`` seconds after it.  A jump backwards or forwards by more than
    ``max_gap_s`` (a new recording, a receiver restart) re-anchors instead of stalling.
    """

    def __init__(self, clock: Callable[[], float] = time.monotonic, max_gap_s: float = 10.0):
        self._clock = clock
        self.max_gap_s = max_gap_s
        self._anchor: tuple[float, float] | None = None  # (stream time, clock time)
        self._last_t = math.nan

    def wait_s(self, t: float) -> float:
        """Seconds until an item of stream time ``t`` [s] is due (0: release it now)."""
        now = self._clock()
        if self._anchor is None or not (
                self._last_t - 1e-6 <= t <= self._last_t + self.max_gap_s):
            self._anchor = (t, now)
        return max(0.0, (t - self._anchor[0]) - (now - self._anchor[1]))

    def released(self, t: float) -> None:
        """Record that the item of stream time ``t`` has been released."""
        self._last_t = t

    def due(self, t: float | None) -> bool:
        """Whether an item of stream time ``t`` [s] (None: untimed, always due) may be released
        now; a due timed item is recorded as released."""
        if t is None:
            return True
        if self.wait_s(t) > 0.0:
            return False
        self.released(t)
        return True


class SourceReader:
    """Reads a source in a thread of its own and hands the bytes to the driver's thread.

    For a driver on an event loop (a ROS executor): while the source has nothing, nothing runs
    (the thread blocks in ``select`` on the port or socket, or sleeps until a reconnection is
    due) instead of a timer polling it. ``post(fn)`` must run ``fn()`` on the driver's thread
    (it may return before that). Each chunk read is handed over as ``feed(data)``; it returns
    the seconds until the driver wants ``release()`` (records a :class:`Pacer` holds back) or
    None, and ``release()`` returns the same. The thread reads on only when nothing is held
    back, so a file is read no further ahead of the decoder than one chunk and a paced one
    keeps its recorded timing. The thread ends at the end of a file or at :meth:`stop`;
    ``on_error(err)`` (on the reader's thread) is told of anything unexpected, and reading
    resumes after ``retry_s``.
    """

    def __init__(self, source: ByteSource, post: Callable[[Callable[[], None]], None],
                 feed: Callable[[bytes], float | None], release: Callable[[], float | None],
                 max_bytes: int, on_error: Callable[[Exception], None] = lambda err: None,
                 wait_s: float = 0.5, retry_s: float = 0.5):
        self.source, self.max_bytes = source, max_bytes
        self._post, self._feed, self._release, self._on_error = post, feed, release, on_error
        # The longest block in select: how soon stop() is noticed.
        self._wait_s, self._retry_s = wait_s, retry_s
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"reader {source.name}",
                                        daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        """End the thread and wait for it (at most ``wait_s`` plus what the driver runs)."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join()

    def sleep(self, seconds: float) -> bool:
        """Wait ``seconds`` or until :meth:`stop`; whether it was stopped."""
        return self._stop.wait(seconds)

    def _run(self) -> None:
        due = None  # seconds until the driver wants release(), None: nothing held back
        while not self._stop.is_set():
            try:
                if due is not None:
                    if self.sleep(due):
                        return
                    due = self._on_driver(self._release)
                    continue
                data = self.source.read(self.max_bytes, self._wait_s)
                if data:
                    due = self._on_driver(self._feed, data)
                elif isinstance(self.source, FileSource) and self.source.finished:
                    return
                elif not self.source.connected:
                    self.sleep(self.source.reconnect_in_s())
            except Exception as err:  # noqa: BLE001 - the reader must outlive any fault
                self._on_error(err)
                self.sleep(self._retry_s)

    def _on_driver(self, fn, *args) -> float | None:
        """``fn(*args)`` run on the driver's thread; its result, once it has run."""
        done, result = threading.Event(), [None]

        def task() -> None:
            try:
                result[0] = fn(*args)
            finally:
                done.set()
        self._post(task)
        while not done.wait(self._wait_s):
            if self._stop.is_set():
                return None
        return result[0]


def open_source(url: str, **kwargs) -> ByteSource:
    """The byte source a URL names (see module docstring); ``kwargs`` go to its constructor.

    Raises
    ------
    ValueError
        An unknown scheme or a malformed URL (a configuration error, not a runtime fault).
    """
    parts = urlsplit(url)
    query = {k: v[-1] for k, v in parse_qs(parts.query).items()}
    try:
        if parts.scheme == "serial":
            if not parts.path:
                raise ValueError("no device path")
            baud = int(query.get("baud", 115200))
            if baud <= 0:
                raise ValueError(f"baud rate {baud} is not positive")
            return SerialSource(parts.path, baud, **kwargs)
        if parts.scheme in ("tcp", "tcp-listen"):
            if parts.port is None:
                raise ValueError("no port")
            if parts.scheme == "tcp":
                return TcpClientSource(parts.hostname or "127.0.0.1", parts.port, **kwargs)
            return TcpServerSource(parts.hostname or "127.0.0.1", parts.port, **kwargs)
        if parts.scheme == "file":
            if not parts.path:
                raise ValueError("no file path")
            return FileSource(parts.path, query.get("pace", "recorded"), **kwargs)
    except ValueError as err:
        raise ValueError(f"source {url!r}: {err}") from None
    raise ValueError(f"source {url!r}: scheme must be serial, tcp, tcp-listen or file")
