"""The typed client: ``ecmxf.connect()`` and what a :class:`Client` does.

A thin layer over the generated stubs (``ecmxf.v1``): names instead of
enum numbers, Python values instead of ``Value`` messages, iterators
instead of streams, exceptions with the daemon's error details. Everything
the API offers stays reachable through ``client.stub(...)``.
"""

from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, Iterable, Iterator, List, Mapping, Optional, Sequence, Union

import grpc

from . import errors, values
from .v1 import (
    admin_pb2,
    admin_pb2_grpc,
    common_pb2,
    master_pb2,
    master_pb2_grpc,
    pdo_pb2,
    pdo_pb2_grpc,
    sdo_pb2,
    sdo_pb2_grpc,
)

SYSTEM_SOCKET = "/run/ecmxfd/ecmxfd.sock"

# grpc-core sends a Unix socket's path as the HTTP/2 :authority, which the
# daemon's HTTP/2 stack (hyperium/h2) rejects as malformed: name it
# "localhost", as grpc-go does (proto/README.md, "Connecting").
UNIX_OPTIONS = [("grpc.default_authority", "localhost")]

# 64 MiB: a full SII image or a long object list fits one answer.
_MESSAGE_LIMIT = [("grpc.max_receive_message_length", 64 << 20)]


def default_socket() -> str:
    """Where ``ecmxfctl`` looks, in the same order: ``$ECMXF_SOCKET``; your
    own daemon's socket (root: ``/run/ecmxfd/ecmxfd.sock``, others
    ``$XDG_RUNTIME_DIR/ecmxfd.sock`` or ``/tmp/ecmxfd-UID.sock``) if it
    exists; else the system service's ``/run/ecmxfd/ecmxfd.sock`` if that
    exists; else your own (for the error message)."""
    env = os.environ.get("ECMXF_SOCKET")
    if env:
        return env
    uid = os.getuid()
    if uid == 0:
        own = SYSTEM_SOCKET
    elif os.environ.get("XDG_RUNTIME_DIR"):
        own = os.path.join(os.environ["XDG_RUNTIME_DIR"], "ecmxfd.sock")
    else:
        own = f"/tmp/ecmxfd-{uid}.sock"
    if os.path.exists(own) or not os.path.exists(SYSTEM_SOCKET):
        return own
    return SYSTEM_SOCKET


def _state_name(s: int) -> str:
    return common_pb2.EcatState.Name(s).replace("ECAT_STATE_", "")


def _state_number(s: Union[str, int]) -> int:
    if isinstance(s, int):
        return s
    key = s.strip().upper().replace("-", "_").replace(" ", "_")
    key = {"PREOP": "PRE_OP", "SAFEOP": "SAFE_OP"}.get(key, key)
    try:
        return common_pb2.EcatState.Value("ECAT_STATE_" + key)
    except ValueError:
        raise ValueError(f"unknown EtherCAT state {s!r}: INIT, PRE_OP, BOOT, SAFE_OP or OP") from None


@dataclass(frozen=True)
class Slave:
    """A slave on the ring, as ``ListSlaves`` found it."""

    position: int
    name: str
    vendor_id: int
    product_code: int
    revision: int
    state: str
    alias: int = 0
    al_status_code: int = 0
    al_status_text: str = ""
    input_bytes: int = 0
    output_bytes: int = 0


@dataclass(frozen=True)
class Entry:
    """One named entry of the process image (``GetLayout``)."""

    name: str
    slave: int
    direction: str  # "input" or "output"
    index: int
    subindex: int
    bit_offset: int
    bit_length: int
    data_type: str  # "UNSIGNED16", ...
    # The variable name configuration tools give it ("" when none): the
    # ENI's ("WheelRearLeft.Inputs.Status word"), else "<slave>.<PDO>.<entry>".
    # Taken wherever ``name`` is: stream_inputs, lease.write, samples.
    variable: str = ""


@dataclass(frozen=True)
class Layout:
    """The process image: sizes, cycle and every named entry."""

    input_bytes: int
    output_bytes: int
    cycle_us: int
    entries: List[Entry]

    def inputs(self) -> List[Entry]:
        return [e for e in self.entries if e.direction == "input"]

    def outputs(self) -> List[Entry]:
        return [e for e in self.entries if e.direction == "output"]

    def entry(self, name: str) -> Entry:
        """The entry with this name or variable name (KeyError if none)."""
        for e in self.entries:
            if name in (e.name, e.variable) and name:
                return e
        raise KeyError(name)


class Sample(dict):
    """One input frame: a dict of entry name to value, plus ``seq`` (the DC
    cycle, +1 per cycle), ``time_ns``, ``monotonic_ns`` (host
    CLOCK_MONOTONIC when the frame arrived), ``gap`` (cycles the daemon
    never received just before) and ``lost`` (frames this reader missed)."""

    seq: int
    time_ns: int
    monotonic_ns: int
    gap: int
    lost: int


@dataclass(frozen=True)
class Event:
    """A daemon event (``Diagnostics.StreamEvents``)."""

    kind: str  # "STATE_CHANGE", "EMERGENCY", "RECOVERING", ...
    time_ns: int
    detail: str
    slave: int
    cause: str
    message: Any = field(repr=False)  # the ecmxf.v1.Event itself


def _call(fn, *args, **kwargs):
    try:
        return fn(*args, **kwargs)
    except grpc.RpcError as e:
        raise errors.from_rpc_error(e) from None


def _stream(it):
    try:
        yield from it
    except grpc.RpcError as e:
        if e.code() == grpc.StatusCode.CANCELLED:
            return
        raise errors.from_rpc_error(e) from None


class Client:
    """A connection to ecmxfd. Use :func:`connect`; close it, or use it as a
    context manager."""

    def __init__(self, channel: grpc.Channel, token: Optional[str] = None, timeout: float = 5.0) -> None:
        self.channel = channel
        self.timeout = timeout
        self._metadata = [("authorization", f"Bearer {token}")] if token else []
        self._master = master_pb2_grpc.MasterStub(channel)
        self._slaves = master_pb2_grpc.SlavesStub(channel)
        self._state = master_pb2_grpc.StateStub(channel)
        self._sdo = sdo_pb2_grpc.SdoStub(channel)
        self._pdo = pdo_pb2_grpc.ProcessDataStub(channel)
        self._diag = admin_pb2_grpc.DiagnosticsStub(channel)

    # -- plumbing -----------------------------------------------------
    def close(self) -> None:
        self.channel.close()

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def stub(self, stub_class):
        """Any generated stub on this connection, e.g.
        ``client.stub(ecmxf.v1.cia402_pb2_grpc.Cia402Stub)``; pass
        ``metadata=client.metadata`` when a token is in use."""
        return stub_class(self.channel)

    @property
    def metadata(self):
        return list(self._metadata)

    def _unary(self, method, request, timeout: Optional[float] = None):
        return _call(method, request, timeout=timeout or self.timeout, metadata=self._metadata)

    # -- the network --------------------------------------------------
    def status(self) -> master_pb2.MasterStatus:
        """The engine's status (phase, health, counters) as the message."""
        return self._unary(self._master.GetStatus, master_pb2.GetStatusRequest())

    def slaves(self) -> List[Slave]:
        """The slaves on the ring, by position."""
        r = self._unary(self._slaves.ListSlaves, master_pb2.ListSlavesRequest())
        return [
            Slave(
                position=s.position,
                name=s.name,
                vendor_id=s.vendor_id,
                product_code=s.product_code,
                revision=s.revision,
                state=_state_name(s.state),
                alias=s.alias,
                al_status_code=s.al_status_code,
                al_status_text=s.al_status_text,
                input_bytes=s.input_bytes,
                output_bytes=s.output_bytes,
            )
            for s in r.slaves
        ]

    def state(self, slave: Optional[int] = None) -> str:
        """The network's state (the lowest of all slaves'), or one slave's:
        ``"INIT"``, ``"PRE_OP"``, ``"BOOT"``, ``"SAFE_OP"``, ``"OP"``."""
        req = master_pb2.GetStateRequest() if slave is None else master_pb2.GetStateRequest(slave=slave)
        return _state_name(self._unary(self._state.GetState, req).state)

    def states(self) -> Dict[int, str]:
        """Every slave's state by position."""
        r = self._unary(self._state.GetState, master_pb2.GetStateRequest())
        return {s.position: _state_name(s.state) for s in r.slaves}

    def set_state(
        self, state: Union[str, int], slave: Optional[int] = None, wait: bool = True, timeout: float = 10.0
    ) -> str:
        """Request a state (``"op"``, ``"safe_op"``, ...) for the network or
        one slave; with ``wait`` until it is reached or ``timeout`` passes."""
        req = master_pb2.SetStateRequest(state=_state_number(state), wait=wait, timeout_ms=int(timeout * 1000))
        if slave is not None:
            req.slave = slave
        return _state_name(self._unary(self._state.SetState, req, timeout=timeout + 2.0).state)

    # -- SDO -----------------------------------------------------------
    def sdo_read(
        self,
        slave: int,
        index: int,
        subindex: int = 0,
        type: Optional[Union[str, int]] = None,
        complete_access: bool = False,
    ) -> Optional[values.PyValue]:
        """An object's value: typed from the slave's dictionary when known,
        else from ``type`` (``"u32"``, ``"i16"``, ``"string"``...), else the
        raw bytes. Raises :class:`ecmxf.SdoAbort` with the abort code."""
        address = _sdo_address(slave, index, subindex, type, complete_access)
        r = self._unary(self._sdo.Upload, sdo_pb2.SdoUploadRequest(**address))
        v = values.to_python(r.value) if r.HasField("value") else None
        return bytes(r.raw) if v is None else v

    def sdo_write(
        self,
        slave: int,
        index: int,
        subindex: int,
        value: values.PyValue,
        type: Optional[Union[str, int]] = None,
        complete_access: bool = False,
    ) -> int:
        """Write an object; the daemon checks ``value`` against its type
        (from the dictionary or ``type``). Returns the bytes written."""
        address = _sdo_address(slave, index, subindex, type, complete_access)
        r = self._unary(self._sdo.Download, sdo_pb2.SdoDownloadRequest(value=values.to_value(value), **address))
        return r.bytes_written

    # -- process data ---------------------------------------------------
    def layout(self) -> Layout:
        """The process image's named entries with their bit offsets."""
        r = self._unary(self._pdo.GetLayout, pdo_pb2.GetLayoutRequest())
        return Layout(
            input_bytes=r.input_bytes,
            output_bytes=r.output_bytes,
            cycle_us=r.cycle_us,
            entries=[
                Entry(
                    name=e.name,
                    slave=e.slave,
                    direction=pdo_pb2.Direction.Name(e.direction).replace("DIRECTION_", "").lower(),
                    index=e.index,
                    subindex=e.subindex,
                    bit_offset=e.bit_offset,
                    bit_length=e.bit_length,
                    data_type=common_pb2.DataType.Name(e.data_type).replace("DATA_TYPE_", ""),
                    variable=e.variable,
                )
                for e in r.entries
            ],
        )

    def stream_inputs(
        self,
        entries: Optional[Sequence[str]] = None,
        every: int = 1,
        *,
        on_change: bool = False,
        duration: Optional[float] = None,
        count: Optional[int] = None,
    ) -> Iterator[Sample]:
        """Input frames as they arrive, each a :class:`Sample` (a dict of
        entry name to value). ``entries``: the names to decode (default:
        every input entry); ``every``: every n-th cycle; ``on_change``: only
        when a value changed. Ends after ``duration`` seconds or ``count``
        samples, or when the caller stops iterating."""
        names = list(entries) if entries is not None else [e.name for e in self.layout().inputs()]
        if not names:
            raise errors.FailedPrecondition("the network has no input entries to stream")
        req = pdo_pb2.StreamInputsRequest(entries=names, decimation=max(1, every), on_change=on_change)
        call = self._pdo.StreamInputs(req, metadata=self._metadata)
        end = None if duration is None else time.monotonic() + duration
        n = 0
        try:
            for m in _stream(call):
                s = Sample((v.name, values.to_python(v.value)) for v in m.values)
                s.seq, s.time_ns, s.monotonic_ns, s.gap, s.lost = m.seq, m.time_ns, m.monotonic_ns, m.gap, m.lost
                yield s
                n += 1
                if (count is not None and n >= count) or (end is not None and time.monotonic() >= end):
                    return
        finally:
            call.cancel()

    def inputs_array(
        self,
        entries: Optional[Sequence[str]] = None,
        every: int = 1,
        *,
        duration: Optional[float] = None,
        count: Optional[int] = None,
    ):
        """The same samples as one numpy structured array: a ``seq`` column
        and one column per entry (``arr["seq"]``, ``arr["statusword"]``).
        Needs numpy (``pip install "ecmxf[numpy]"``)."""
        try:
            import numpy as np
        except ImportError:
            raise ImportError('inputs_array needs numpy: pip install "ecmxf[numpy]"') from None
        if duration is None and count is None:
            raise ValueError("inputs_array needs duration= or count= (it collects before it returns)")
        inputs = self.layout().inputs()
        layout = {e.name: e for e in inputs}
        layout.update({e.variable: e for e in inputs if e.variable})
        names = list(entries) if entries is not None else [e.name for e in inputs]
        rows = [
            (s.seq, *(s.get(n) for n in names))
            for s in self.stream_inputs(names, every, duration=duration, count=count)
        ]
        dtype = [("seq", "u8")] + [(n, _numpy_type(layout.get(n))) for n in names]
        return np.array(rows, dtype=dtype)

    def lease(self, slaves: Optional[Iterable[int]] = None, ttl: float = 2.0) -> "Lease":
        """Own the outputs of ``slaves`` (default: all) while the ``with``
        block runs: the lease is kept alive in the background and released
        at the end. Write with ``lease.write(name=value, ...)``."""
        return Lease(self, list(slaves or []), ttl)

    def events(self) -> Iterator[Event]:
        """The daemon's events as they happen (state changes, emergencies,
        recoveries, ...), until the caller stops iterating."""
        call = self._diag.StreamEvents(admin_pb2.StreamEventsRequest(), metadata=self._metadata)
        try:
            for m in _stream(call):
                yield Event(
                    kind=admin_pb2.EventKind.Name(m.kind).replace("EVENT_KIND_", ""),
                    time_ns=m.time_ns,
                    detail=m.detail,
                    slave=m.slave,
                    cause=m.cause,
                    message=m,
                )
        finally:
            call.cancel()


def _sdo_address(slave: int, index: int, subindex: int, type, complete_access: bool) -> Dict[str, Any]:
    """The fields an SDO upload and download share."""
    return dict(
        slave=slave,
        index=index,
        subindex=subindex,
        complete_access=complete_access,
        data_type=values.data_type(type),
    )


def _numpy_type(entry: Optional[Entry]) -> str:
    t = entry.data_type if entry else ""
    return {
        "BOOLEAN": "?",
        "INTEGER8": "i1",
        "INTEGER16": "i2",
        "INTEGER32": "i4",
        "INTEGER64": "i8",
        "UNSIGNED8": "u1",
        "UNSIGNED16": "u2",
        "UNSIGNED32": "u4",
        "UNSIGNED64": "u8",
        "REAL32": "f4",
        "REAL64": "f8",
    }.get(t, "O")


class Lease:
    """Ownership of some slaves' outputs (``ProcessData.AcquireLease``),
    kept alive by a background thread at a third of its time to live."""

    def __init__(self, client: Client, slaves: List[int], ttl: float) -> None:
        self.client = client
        self.slaves = slaves
        self.ttl = ttl
        self.id: Optional[str] = None
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self.error: Optional[errors.Error] = None

    def __enter__(self) -> "Lease":
        c = self.client
        r = c._unary(c._pdo.AcquireLease, pdo_pb2.AcquireLeaseRequest(slaves=self.slaves, ttl_ms=int(self.ttl * 1000)))
        self.id = r.id
        self.slaves = list(r.slaves)
        self._thread = threading.Thread(target=self._keep_alive, name="ecmxf-lease", daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    def _keep_alive(self) -> None:
        c = self.client
        while not self._stop.wait(self.ttl / 3):
            try:
                c._unary(c._pdo.KeepAlive, pdo_pb2.KeepAliveRequest(lease_id=self.id))
            except errors.Error as e:
                # Told to the next write (which the daemon refuses anyway).
                self.error = e
                return

    def write(self, entries: Optional[Mapping[str, values.PyValue]] = None, **named: values.PyValue) -> int:
        """Write output entries by name: ``lease.write(controlword=6)`` or
        ``lease.write({"axis1.controlword": 6})``. All values of one call
        reach the wire in the same cycle. Returns the writes applied."""
        if self.id is None:
            raise errors.FailedPrecondition("the lease is not held: use it in a with block")
        if self.error is not None:
            raise self.error
        items = dict(entries or {}, **named)
        writes = [pdo_pb2.OutputWrite(entry=k, value=values.to_value(v)) for k, v in items.items()]
        c = self.client
        r = c._unary(c._pdo.WriteOutputs, pdo_pb2.WriteOutputsRequest(lease_id=self.id, writes=writes))
        return r.applied

    def release(self) -> None:
        """Give the outputs back (the daemon keeps their last values)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        if self.id is not None:
            lease_id, self.id = self.id, None
            c = self.client
            try:
                c._unary(c._pdo.ReleaseLease, pdo_pb2.ReleaseLeaseRequest(lease_id=lease_id))
            except errors.NotFound:
                pass  # expired already


_START_HINT = (
    "is ecmxfd running? Start it (`systemctl start ecmxfd`, or `ecmxfd --sim` to try the simulator), "
    "or say where it listens with socket= / $ECMXF_SOCKET, or address= for TCP"
)


def _check_socket(path: str) -> None:
    """Fails at once, in ecmxfctl's words, where nothing can answer: no
    socket file, a file nobody listens on, a socket not ours to use."""
    import socket as _socket

    probe = _socket.socket(_socket.AF_UNIX, _socket.SOCK_STREAM)
    probe.settimeout(1.0)
    try:
        probe.connect(path)
    except FileNotFoundError:
        why = "no socket there"
    except ConnectionRefusedError:
        why = "nothing listens on the socket (stale file)"
    except PermissionError:
        why = "permission denied on the socket (be in its group, see api.socket_group)"
    except OSError:
        return  # let gRPC say what it is
    else:
        return
    finally:
        probe.close()
    raise errors.Unreachable(f"cannot reach ecmxfd at {path}: {why}: {_START_HINT}")


def connect(
    socket: Optional[Union[str, Path]] = None,
    address: Optional[str] = None,
    token: Optional[str] = None,
    *,
    ca: Optional[Union[str, Path]] = None,
    cert: Optional[Union[str, Path]] = None,
    key: Optional[Union[str, Path]] = None,
    timeout: float = 5.0,
    wait: float = 5.0,
) -> Client:
    """Connect to ecmxfd: on its Unix socket (``socket``, else found as
    ``ecmxfctl`` finds it: :func:`default_socket`), or over TCP with TLS
    (``address`` "host:port", with ``ca`` for a private CA and ``cert`` +
    ``key`` for a client certificate). ``token`` (default
    ``$ECMXF_TOKEN``) authenticates. ``timeout`` is each call's deadline;
    ``wait`` how long to wait for the daemon to answer at all."""
    token = token if token is not None else os.environ.get("ECMXF_TOKEN") or None
    address = address or os.environ.get("ECMXF_CONNECT") or None
    if address:
        read = lambda p: Path(p).read_bytes() if p else None  # noqa: E731
        creds = grpc.ssl_channel_credentials(read(ca or os.environ.get("ECMXF_CA")), read(key), read(cert))
        target = address.removeprefix("https://")
        channel = grpc.secure_channel(target, creds, options=_MESSAGE_LIMIT)
        where = address
    else:
        path = str(socket or default_socket())
        _check_socket(path)
        channel = grpc.insecure_channel("unix:" + path, options=UNIX_OPTIONS + _MESSAGE_LIMIT)
        where = path
    try:
        grpc.channel_ready_future(channel).result(timeout=wait)
    except grpc.FutureTimeoutError:
        channel.close()
        hint = "is ecmxfd running? (`ecmxfd --sim` to try the simulator)"
        raise errors.Unreachable(f"cannot reach ecmxfd at {where} within {wait:g} s: {hint}") from None
    return Client(channel, token=token, timeout=timeout)
