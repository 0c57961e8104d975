"""Shared fixtures: one quick simulated recording per test session, generated on demand."""

from __future__ import annotations

import os

os.environ.setdefault("FUZZYSLAM_NO_PROGRESS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")
