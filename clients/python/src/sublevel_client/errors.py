"""Errors of the service as one exception type."""

from __future__ import annotations

import re
from typing import Optional

import grpc

__all__ = ["SublevelError", "parse_field"]

_FIELD = re.compile(r"invalid argument `([^`]*)`")


def parse_field(message: str) -> Optional[str]:
    """The request field an INVALID_ARGUMENT message names, e.g. ``poses[3].pose.rotation`` in
    "invalid argument `poses[3].pose.rotation`: ..."; None when the message names none."""
    m = _FIELD.search(message or "")
    return m.group(1) if m else None


class SublevelError(Exception):
    """A failed call to the service.

    Attributes:
        code: the gRPC status code (``grpc.StatusCode``), e.g. ``INVALID_ARGUMENT``, ``NOT_FOUND``,
            ``RESOURCE_EXHAUSTED``, ``UNIMPLEMENTED``, ``UNAVAILABLE``.
        message: the server's message (its details).
        field: for INVALID_ARGUMENT, the request field the server named in backticks (e.g.
            ``poses[0].pose.rotation``, ``queries[1].margin``); None otherwise.
    """

    def __init__(self, code: grpc.StatusCode, message: str, field: Optional[str] = None):
        self.code = code
        self.message = message
        self.field = field
        super().__init__(f"{code.name}: {message}")

    @classmethod
    def from_rpc_error(cls, e: grpc.RpcError) -> "SublevelError":
        """Wraps a ``grpc.RpcError`` (as raised by a stub call or a stream)."""
        code = e.code() if hasattr(e, "code") else grpc.StatusCode.UNKNOWN
        message = e.details() if hasattr(e, "details") else str(e)
        message = message or ""
        return cls(code, message, parse_field(message))
