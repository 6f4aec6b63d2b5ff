"""Exceptions for bad data: each names the file (and line) and says how to fix it."""

from __future__ import annotations


class DataFormatError(ValueError):
    """A recording, homography or map file is malformed (message names the file and line)."""


class DataRootError(FileNotFoundError):
    """The ETH/UCY data root is missing, incomplete or corrupt (message says how to fix it)."""
