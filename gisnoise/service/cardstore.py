"""The service's model-card store: versioned card files in ``<data_dir>/cards/<id>/v<N>.json``.

An upload never overwrites: a card whose id was never used becomes version 1; an
identical re-upload returns the existing version; a different card with an
existing id is refused (409) unless a new version is asked for, which then
becomes version N + 1.  ``get`` returns the latest version unless one is named.

``id@N`` is an immutable reference: version numbers of an id only ever increase.  The
highest number issued is kept in ``<id>/highest_version.json`` (written atomically, before
the card file, so a number is never issued twice even after a crash), which deletes leave in
place: after deleting version 2 of 2, or every version, the next upload of the id is version 3.
A card stored here has passed the plausibility guard (:func:`gisnoise.model.check_card`) on
upload; one stored before the guard refused it is refused when read (422 naming the field).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import stat
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from gisnoise import jsonio
from gisnoise.limits import SAFE_ID_PATTERN
from gisnoise.model import ModelCard
from gisnoise.model import cards as gcards
from gisnoise.service.errors import ApiError
from gisnoise.service.storage import storage_error, storage_failure

__all__ = ["CardStore", "StoredCard", "ID_PATTERN"]

ID_PATTERN = SAFE_ID_PATTERN
_ID_RE = re.compile(ID_PATTERN)
_VERSION_RE = re.compile(r"^v(\d+)\.json$")
HIGHEST_FILE = "highest_version.json"
"""File in a card's folder holding the highest version ever issued for its id (``{"highest_version": N}``)."""
SETTLED_S = 2.0
"""Age (s) of a card folder's modification time from which its listing is kept (see ``CardStore._versions``)."""


@dataclass(frozen=True)
class StoredCard:
    card: ModelCard
    version: int
    path: Path


def check_id(card_id: str, field: str = "id") -> str:
    if not isinstance(card_id, str) or not _ID_RE.fullmatch(card_id):
        raise ApiError(422, f"{field}: card id {card_id!r} is not valid (letters, digits, '.', '_', '-', no leading "
                            "dot, no reserved device name, at most 128 characters)", field=field)
    return card_id


class CardStore:
    """Versioned model cards on disk."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self._lock = threading.Lock()
        self._cache: dict[Path, tuple[int, int, ModelCard]] = {}
        self._listings: dict[str, tuple[tuple[int, int, int], tuple[int, ...]]] = {}

    def seed(self, folder: Path | None) -> int:
        """Copy the cards of ``folder`` into a store that does not exist yet; returns how many."""
        if self.root.exists():
            return 0
        self.root.mkdir(parents=True)
        n = 0
        if folder is None:
            return 0
        try:
            for p in sorted(Path(folder).glob("*.json")):
                try:
                    card = gcards.load(p)
                except gcards.CardError:
                    continue
                if _ID_RE.match(card.id):
                    self.put(card)
                    n += 1
        except BaseException:  # a full disk, say: the store does not exist yet, so the next start seeds it
            shutil.rmtree(self.root, ignore_errors=True)
            raise
        return n

    def _versions(self, card_id: str) -> list[int]:
        """The versions stored for ``card_id``, sorted.

        The listing is kept by the card folder's stat (device, inode, modification time): adding or removing a
        version changes the folder's modification time.  A listing is kept only once that time lies
        :data:`SETTLED_S` in the past, so a change within the file system's timestamp granularity of the last one
        cannot go unseen.
        """
        d = self.root / card_id
        try:
            st = os.stat(d)
        except (OSError, ValueError):  # as Path.is_dir: missing, not reachable, or a name the OS refuses
            return []
        if not stat.S_ISDIR(st.st_mode):
            return []
        key = (st.st_dev, st.st_ino, st.st_mtime_ns)
        hit = self._listings.get(card_id)
        if hit is not None and hit[0] == key:
            return list(hit[1])
        out = []
        for p in d.iterdir():
            m = _VERSION_RE.match(p.name)
            if m:
                out.append(int(m.group(1)))
        out.sort()
        if time.time_ns() - st.st_mtime_ns > SETTLED_S * 1e9:
            if len(self._listings) > 1024:
                self._listings.clear()
            self._listings[card_id] = (key, tuple(out))
        return out

    def ids(self) -> list[str]:
        if not self.root.is_dir():
            return []
        return sorted(p.name for p in self.root.iterdir() if p.is_dir() and self._versions(p.name))

    def versions(self, card_id: str) -> list[int]:
        return self._versions(check_id(card_id))

    def get(self, card_id: str, version: int | None = None, *, field: str = "id") -> StoredCard:
        check_id(card_id, field)
        vs = self._versions(card_id)
        if not vs:
            raise ApiError(404, f"{field}: no card with id {card_id!r}", field=field)
        v = vs[-1] if version is None else version
        if v not in vs:
            raise ApiError(404, f"version: card {card_id!r} has no version {v} (versions: "
                                f"{', '.join(map(str, vs))})", field="version")
        path = self.root / card_id / f"v{v}.json"
        try:
            card = self._load(path)
        except gcards.CardError as exc:  # stored before the guard refused it: named as the store names it
            raise type(exc)(str(exc).replace(str(path), f"stored card {card_id}@{v}"), field=exc.field) from None
        return StoredCard(card, v, path)

    def _load(self, path: Path) -> ModelCard:
        """A card file, parsed once (versions are never rewritten; the cache key is also the file's stat)."""
        st = path.stat()
        hit = self._cache.get(path)
        if hit is not None and hit[:2] == (st.st_mtime_ns, st.st_size):
            return hit[2]
        card = gcards.load(path)
        self._cache[path] = (st.st_mtime_ns, st.st_size, card)
        return card

    def resolve(self, ref: str, *, field: str) -> ModelCard:
        """A card from a reference ``id`` or ``id@version``; errors name ``field``."""
        card_id, _, ver = ref.partition("@")
        version = None
        if ver:
            if not ver.isdigit():
                raise ApiError(422, f"{field}: version after '@' must be a number, got {ver!r}", field=field)
            version = int(ver)
        try:
            return self.get(card_id, version, field=field).card
        except ApiError as exc:
            if exc.status == 404:  # the reference is the field: named once, at the head of the message
                what = str(exc).removeprefix(f"{exc.field}: ") if exc.field else str(exc)
                raise ApiError(422, f"{field}: {what}", field=field) from None
            raise
        except gcards.CardError as exc:  # a stored card the guard refuses: the request's reference is the field
            raise ApiError(422, f"{field}: {exc}", field=field) from None

    def _highest(self, card_id: str, versions: list[int]) -> int:
        """The highest version ever issued for ``card_id``: its record, or its highest stored version."""
        top = versions[-1] if versions else 0
        try:
            doc = json.loads((self.root / card_id / HIGHEST_FILE).read_text(encoding="utf-8"))
            n = doc.get("highest_version") if isinstance(doc, dict) else None
        except (OSError, ValueError):  # no record yet (a store older than it), or an unreadable one
            return top
        return max(top, n) if isinstance(n, int) and not isinstance(n, bool) else top

    def _record_highest(self, card_id: str, version: int) -> None:
        """Record ``version`` as the highest issued for ``card_id`` (temporary file and atomic replace)."""
        d = self.root / card_id
        d.mkdir(parents=True, exist_ok=True)
        jsonio.write_json({"highest_version": int(version)}, d / HIGHEST_FILE)

    def put(self, card: ModelCard, *, new_version: bool = False) -> tuple[StoredCard, bool]:
        """Store a card; returns (stored card, created).

        Identical to the latest version: nothing is written (created False).
        Different from an existing id: 409 unless ``new_version``.
        """
        check_id(card.id)
        with self._lock:
            vs = self._versions(card.id)
            v = self._highest(card.id, vs) + 1  # never a number issued before, deleted or not
            if vs:
                try:
                    latest: StoredCard | None = self.get(card.id)
                except gcards.CardError:  # a stored version the guard refuses: the upload differs from it
                    latest = None
                if latest is not None and latest.card == card:
                    return latest, False
                if not new_version:
                    raise ApiError(409, f"id: a different card {card.id!r} exists (version {vs[-1]}); "
                                        f"upload with new_version=true to add version {v}, "
                                        f"or choose another id", field="id")
            d = self.root / card.id
            path = d / f"v{v}.json"
            tmp = d / f".v{v}.json.tmp"
            new_folder = not d.exists()
            try:
                d.mkdir(parents=True, exist_ok=True)
                tmp.write_text(gcards.dumps(card), encoding="utf-8")
                self._record_highest(card.id, v)  # before the card: a crash in between skips v, never reuses it
                os.link(tmp, path)  # fails if the version appeared meanwhile: never overwrite
            except OSError as exc:  # a full disk, say: nothing of the upload is left
                tmp.unlink(missing_ok=True)
                (d / f".{HIGHEST_FILE}.tmp").unlink(missing_ok=True)
                if new_folder:
                    shutil.rmtree(d, ignore_errors=True)
                failure = storage_failure(exc, near=self.root)
                if failure is not None:
                    raise storage_error(failure, f"card {card.id!r} was not stored") from None
                raise
            tmp.unlink()
            return StoredCard(card, v, path), True

    def delete(self, card_id: str, version: int | None = None) -> list[int]:
        """Delete one version or all; returns the deleted versions.

        The record of the highest version issued stays (the folder holds it once no version is left),
        so a later upload of the id never gets a deleted version's number.
        """
        check_id(card_id)
        with self._lock:
            vs = self._versions(card_id)
            if not vs:
                raise ApiError(404, f"id: no card with id {card_id!r}", field="id")
            if version is not None and version not in vs:
                raise ApiError(404, f"version: card {card_id!r} has no version {version}", field="version")
            d = self.root / card_id
            self._record_highest(card_id, self._highest(card_id, vs))  # a store older than the record gets it
            gone = vs if version is None else [version]
            for v in gone:
                (d / f"v{v}.json").unlink()
                self._cache.pop(d / f"v{v}.json", None)
            if version is None:  # left-over temporary files of interrupted uploads go too
                for p in d.glob(".v*.json.tmp"):
                    p.unlink(missing_ok=True)
            return gone
