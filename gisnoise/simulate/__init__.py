"""Synthetic campaigns: scenarios, flight patterns, microphone audio or levels from a truth card.
"""

from __future__ import annotations

