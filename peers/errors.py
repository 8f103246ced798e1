"""The errors a session or secure-mode setup reports in one line, below every module that
raises them (so session, keys and security import each other in one direction only)."""

from __future__ import annotations


class SessionError(Exception):
    """The Zenoh session could not be configured or opened (reported in one line)."""


class SecurityError(SessionError):
    """Keys could not be made or a secure-mode folder is incomplete (one line)."""
