"""The sim-to-real gap: where a card misses a campaign, which effect explains it, held-out shrinkage.
"""

from __future__ import annotations

