"""Logging set-up: one line per notable event (connections, resets), never one per message."""

from __future__ import annotations

import logging


__all__ = ["setup_logging"]


def setup_logging(level: str = "info") -> None:
    """Configure the root logger for the command line (``--log-level``)."""
    logging.basicConfig(
        level=getattr(logging, level.upper(), logging.INFO),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    logging.getLogger("websockets").setLevel(logging.WARNING)
