"""Model cards by flight phase: which card a map evaluates at each instant of a flight."""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from typing import Any

import numpy as np

from gisnoise.errors import CardError
from gisnoise.model import HemisphereCard, ModelCard, load

__all__ = ["CardSet", "as_cardset", "flying_cards"]


class CardSet:
    """Model cards by flight phase.

    Each card serves its ``phase`` and the extra ``phases`` it lists.  A card's own
    ``phase`` takes precedence over another card's extra phases; two cards with the
    same own phase, or two cards listing the same extra phase (and no card having it
    as its own), are ambiguous and refused.

    Parameters
    ----------
    cards : iterable of ModelCard or path
        Cards, or card files to load.

    Examples
    --------
    >>> from gisnoise.model import ModelCard
    >>> p = {"p1": 13.4, "p2": 0.18, "p3": -0.28, "p4": -0.37, "p5": 1.05, "p6": 0.94, "p7": 40.4}
    >>> h = ModelCard(id="h", vehicle="v", phase="horizontal", ansatz="paper", parameters=p,
    ...               reference_power_w=1500.0, phases=("transition",))
    >>> CardSet([h]).card_for("transition").id
    'h'
    """

    def __init__(self, cards: Iterable[ModelCard | str | os.PathLike[str]] | ModelCard) -> None:
        if isinstance(cards, ModelCard):
            cards = [cards]
        loaded: list[ModelCard] = []
        for c in cards:
            loaded.append(c if isinstance(c, ModelCard) else load(c))
        if not loaded:
            raise CardError("at least one model card is needed", field="card")
        uniq: list[ModelCard] = []
        for c in loaded:
            if not any(c is u for u in uniq):
                uniq.append(c)
        self.cards: tuple[ModelCard, ...] = tuple(uniq)
        own: dict[str, int] = {}
        extra: dict[str, list[int]] = {}
        for i, c in enumerate(self.cards):
            if c.phase in own:
                raise CardError(f"cards {self.cards[own[c.phase]].id!r} and {c.id!r} both serve phase "
                                f"{c.phase!r}; give one card per phase", field="card")
            own[c.phase] = i
            for ph in c.served_phases[1:]:
                extra.setdefault(ph, []).append(i)
        self._index: dict[str, int] = dict(own)
        for ph, idx in extra.items():
            if ph in own:
                continue
            if len(idx) > 1:
                ids = ", ".join(repr(self.cards[i].id) for i in idx)
                raise CardError(f"cards {ids} all serve phase {ph!r}; give one card per phase", field="card")
            self._index[ph] = idx[0]

    def __len__(self) -> int:
        return len(self.cards)

    def __iter__(self) -> Iterator[ModelCard]:
        return iter(self.cards)

    @property
    def phases(self) -> dict[str, str]:
        """Phase -> id of the card serving it."""
        return {ph: self.cards[i].id for ph, i in sorted(self._index.items())}

    def card_for(self, phase: str) -> ModelCard:
        """The card serving ``phase``; :class:`~gisnoise.errors.CardError` if none does."""
        try:
            return self.cards[self._index[phase]]
        except KeyError:
            raise CardError(f"no model card serves phase {phase!r} (cards serve "
                            f"{', '.join(self.phases) or 'nothing'})", field="phase") from None

    def assign(self, phase: Any, t: Any = None, *, source: str = "trajectory", rows: Any = None) -> np.ndarray:
        """Index into :attr:`cards` of every sample's card.

        Raises :class:`~gisnoise.errors.CardError` naming the first unserved phase and
        the range of samples (and times, when ``t`` is given) that have it; ``rows`` are the
        samples' indices in the whole track when ``phase`` holds a subset of it.
        """
        phase = np.asarray(phase).astype(str)
        out = np.empty(phase.shape, dtype=np.intp)
        for ph in map(str, np.unique(phase)):
            m = phase == ph
            if ph not in self._index:
                idx = np.flatnonzero(m)
                i0, i1 = int(idx[0]), int(idx[-1])
                r0, r1 = (i0, i1) if rows is None else (int(rows[i0]), int(rows[i1]))
                when = ""
                if t is not None:
                    tt = np.asarray(t, dtype=float)
                    when = f", t = {tt[i0]:g}-{tt[i1]:g} s"
                tip = "" if not any(isinstance(c, HemisphereCard) for c in self.cards) else (f" (a measured hemisphere serves further phases when imported with "
                                               f"gisnoise card import-hemisphere ... --also-phase {ph})")
                raise CardError(
                    f"{source}: no model card serves phase {ph!r} ({idx.size} samples, samples {r0}-{r1}{when}); "
                    f"cards serve {', '.join(self.phases)}; add a card whose phase or phases include {ph!r}{tip}",
                    field="phase")
            out[m] = self._index[ph]
        return out


def as_cardset(cards: CardSet | Iterable[ModelCard | str | os.PathLike[str]] | ModelCard) -> CardSet:
    """``cards`` as a :class:`CardSet` (itself when it is one)."""
    return cards if isinstance(cards, CardSet) else CardSet(cards)


def flying_cards(traj: Any, cardset: CardSet) -> np.ndarray:
    """The index in ``cardset.cards`` of the card serving each flying sample of ``traj`` (``traj.flying``)."""
    fly = traj.flying
    return cardset.assign(traj.phase[fly], traj.t[fly], source=traj.source, rows=np.flatnonzero(fly))
