"""Shared test configuration.  Helpers that one test module needs live in that module."""

import os

os.environ.setdefault("MPLBACKEND", "Agg")
