"""Errors of the ecmxf API as Python exceptions.

Every error the daemon answers carries a google.rpc.Status with an
ErrorInfo (proto/README.md, "Errors"): its reason names the kind of error,
its metadata the facts. They are read here with grpcio-status, so an SDO
abort arrives as :class:`SdoAbort` with the abort code and its meaning.
"""

from __future__ import annotations

from typing import Dict, Optional

import grpc

__all__ = [
    "Error",
    "InvalidArgument",
    "SdoAbort",
    "FailedPrecondition",
    "PermissionDenied",
    "NotFound",
    "Timeout",
    "Unavailable",
    "Unreachable",
    "DaemonStopping",
]


class Error(Exception):
    """An error answered by ecmxfd (or the connection to it).

    ``code`` is the gRPC status code, ``reason`` the ErrorInfo reason
    (``"SDO_ABORT"``, ``"BAD_ARGUMENT"``, ...), ``metadata`` its facts.
    """

    def __init__(
        self,
        message: str,
        code: Optional[grpc.StatusCode] = None,
        reason: str = "",
        metadata: Optional[Dict[str, str]] = None,
    ) -> None:
        super().__init__(message)
        self.message = message
        self.code = code
        self.reason = reason
        self.metadata: Dict[str, str] = dict(metadata or {})

    def __str__(self) -> str:
        name = self.code.name if self.code is not None else "ERROR"
        return f"{name}: {self.message}"


class InvalidArgument(Error):
    """A bad argument; ``field`` names it (``"slave"``, ``"index"``, ...)."""

    @property
    def field(self) -> str:
        return self.metadata.get("field", "")


class SdoAbort(Error):
    """The slave aborted an SDO transfer."""

    @property
    def abort_code(self) -> int:
        """The CoE abort code, e.g. ``0x06020000``."""
        return int(self.metadata.get("abort_code", "0"), 0)

    @property
    def meaning(self) -> str:
        """What the abort code means (ETG.1000.6 table), e.g. "object does not exist ..."."""
        return self.metadata.get("meaning", "")

    @property
    def slave(self) -> int:
        return int(self.metadata.get("slave", "0"))

    @property
    def object(self) -> str:
        """``"0x6041:00"``."""
        return self.metadata.get("object", "")


class FailedPrecondition(Error):
    """Not possible now: wrong state, a lease held by someone else, ..."""


class PermissionDenied(Error):
    """The caller's role is too low (see the daemon's [api] roles)."""


class NotFound(Error):
    """Something named does not exist (a lease, an entry)."""


class Timeout(Error):
    """The call's deadline passed."""


class Unavailable(Error):
    """The daemon runs but its engine does not (stopped, recovering)."""


class Unreachable(Error):
    """No daemon answers at the socket or address."""


class DaemonStopping(Unavailable):
    """The daemon is stopping: a stream (inputs, events, frames) ended for it.

    Raised instead of a broken-connection error, so a loop over a stream can
    tell a daemon shut down on purpose (ErrorInfo reason ``STOPPING``) from a
    lost one.
    """


_BY_CODE = {
    grpc.StatusCode.INVALID_ARGUMENT: InvalidArgument,
    grpc.StatusCode.ABORTED: SdoAbort,
    grpc.StatusCode.FAILED_PRECONDITION: FailedPrecondition,
    grpc.StatusCode.PERMISSION_DENIED: PermissionDenied,
    grpc.StatusCode.UNAUTHENTICATED: PermissionDenied,
    grpc.StatusCode.NOT_FOUND: NotFound,
    grpc.StatusCode.DEADLINE_EXCEEDED: Timeout,
    grpc.StatusCode.UNAVAILABLE: Unavailable,
}


def from_rpc_error(e: grpc.RpcError) -> Error:
    """The exception for a failed call, with the daemon's ErrorInfo."""
    code = e.code() if hasattr(e, "code") else None
    message = e.details() if hasattr(e, "details") else str(e)
    reason, metadata = "", {}
    try:
        from google.rpc import error_details_pb2
        from grpc_status import rpc_status

        status = rpc_status.from_call(e)
        if status is not None:
            for detail in status.details:
                if detail.Is(error_details_pb2.ErrorInfo.DESCRIPTOR):
                    info = error_details_pb2.ErrorInfo()
                    detail.Unpack(info)
                    reason, metadata = info.reason, dict(info.metadata)
    except (ValueError, ImportError):
        # Details that disagree with the status, or none readable: the
        # status alone still says what failed.
        pass
    if code == grpc.StatusCode.UNAVAILABLE and reason == "STOPPING":
        cls = DaemonStopping
    elif code == grpc.StatusCode.UNAVAILABLE and reason != "NOT_RUNNING":
        cls = Unreachable
        message = f"cannot reach ecmxfd: {message}"
    elif code == grpc.StatusCode.ABORTED and reason != "SDO_ABORT":
        cls = Error
    else:
        cls = _BY_CODE.get(code, Error)
    return cls(message or "", code, reason, metadata)
