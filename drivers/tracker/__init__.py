"""Laser tracker driver: line protocol, TCP client and simulated tracker (see PROTOCOL.md)."""

from ..line_errors import ProtocolError
from .client import TrackerClient, TrackerTimeout
from .protocol import ErrorCode, Ident, Measurement, Status, TrackerError, Weather

__all__ = [
    "ErrorCode",
    "Ident",
    "Measurement",
    "ProtocolError",
    "Status",
    "TrackerClient",
    "TrackerError",
    "TrackerTimeout",
    "Weather",
]
