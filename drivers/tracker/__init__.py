"""Laser tracker driver: line protocol, TCP client and simulated tracker (see PROTOCOL.md)."""

from .client import TrackerClient, TrackerTimeout
from .protocol import ErrorCode, Ident, Measurement, ProtocolError, Status, TrackerError, Weather

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
