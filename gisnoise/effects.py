"""Candidate effects: physically motivated extensions of an ansatz.

Each effect registers here; :func:`gisnoise.model.get_ansatz` imports this module
so extended ansatzes are found by name.  (The effect library is filled in by the
diagnosis module.)
"""

from __future__ import annotations

__all__: list[str] = []
