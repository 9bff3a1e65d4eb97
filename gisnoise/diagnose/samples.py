"""The samples a diagnosis reads: from a campaign folder, a campaign or samples, with the microphones' heights.

The ground-reflection candidate needs each microphone's height above ground;
:func:`with_mic_heights` takes it from ``campaign.json`` when the campaign reader
left it out of the samples' facts.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from gisnoise.errors import InputError
from gisnoise.measure import Samples, read_campaign

__all__ = ["load_samples", "with_mic_heights"]


def load_samples(source: Any) -> Samples:
    """Samples from a campaign folder, a :class:`~gisnoise.measure.campaign.Campaign` or :class:`Samples`.

    Parameters
    ----------
    source : path, Campaign or Samples
        A campaign folder is read with :func:`gisnoise.measure.read_campaign` and its
        microphones' heights completed with :func:`with_mic_heights`.

    Returns
    -------
    Samples

    Raises
    ------
    InputError
        ``source`` is none of these.
    """
    if isinstance(source, Samples):
        return source
    if isinstance(source, (str, os.PathLike)):
        return with_mic_heights(read_campaign(source).samples(), source)
    if hasattr(source, "samples") and callable(source.samples):
        s = source.samples()
        if isinstance(s, Samples):
            return s
    raise InputError(f"campaign: expected a campaign folder, Campaign or Samples, got {type(source).__name__}",
                     field="campaign")


def with_mic_heights(s: Samples, folder: str | os.PathLike[str]) -> Samples:
    """Add the microphones' ``height_agl_m`` from campaign.json to the samples' facts when the reader left it out.

    Parameters
    ----------
    s : Samples
        Samples read from the campaign in ``folder``.
    folder : path
        The campaign folder.

    Returns
    -------
    Samples
        ``s`` with ``meta["microphones"][id]["height_agl_m"]`` filled in where campaign.json
        gives it; ``s`` itself when there is nothing to add or campaign.json cannot be read.
    """
    mics = (s.meta or {}).get("microphones")
    try:
        doc = json.loads((Path(folder) / "campaign.json").read_text(encoding="utf-8-sig"))
    except (OSError, ValueError):
        return s
    heights = {m.get("id"): m["height_agl_m"] for m in doc.get("microphones", [])
               if isinstance(m, Mapping) and isinstance(m.get("height_agl_m"), (int, float))}
    if not heights or not isinstance(mics, Mapping):
        return s
    merged = {k: ({**v, "height_agl_m": heights[k]} if k in heights and "height_agl_m" not in v else v)
              for k, v in mics.items()}
    return s.with_(meta={**s.meta, "microphones": merged})
