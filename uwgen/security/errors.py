"""The one error of the secure link's set-up."""
from __future__ import annotations


class SecurityError(Exception):
    """Security cannot be set up as asked (key file, side lock, sender id): a clear message."""
