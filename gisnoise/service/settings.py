"""Service settings, read from the environment with the ``GISNOISE_`` prefix.

======================================  =============================================
variable                                meaning
======================================  =============================================
``GISNOISE_DATA_DIR``                   folder of the card store, the job database and
                                        job inputs/results (created)
``GISNOISE_API_KEYS``                   comma-separated keys; when set, every write
                                        (upload, job, delete, cancel) needs one in the
                                        ``X-API-Key`` header
``GISNOISE_WORKERS``                    job worker threads (jobs run one per worker)
``GISNOISE_MAX_REQUEST_BYTES``          largest JSON request body (413 beyond)
``GISNOISE_MAX_UPLOAD_BYTES``           largest campaign upload, zipped (413 beyond)
``GISNOISE_MAX_UNZIPPED_BYTES``         largest campaign once unzipped (413 beyond)
``GISNOISE_MAX_CELLS``                  largest grid, cells (413 beyond); also read by
                                        the core's grid module
``GISNOISE_SYNC_WORK_LIMIT``            cells x trajectory samples above which a
                                        contour request becomes a job (202)
``GISNOISE_MAX_TRAJECTORY_SAMPLES``     longest trajectory accepted, samples
``GISNOISE_MAX_WORK``                   cells x time steps of one map, direct or queued
                                        (413 before any work; also read by the core,
                                        :mod:`gisnoise.limits`)
``GISNOISE_SEED_CARDS_DIR``             folder of card JSON files put in an empty store
``GISNOISE_TILE_URL``                   basemap tile URL template of the web page
                                        (empty: no basemap)
``GISNOISE_BASEMAP``                    an MBTiles or PMTiles file served at /basemap as the web
                                        page's basemap (instead of the tile URL)
======================================  =============================================
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Annotated

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

__all__ = ["Settings", "get_settings", "default_seed_cards_dir"]


def default_seed_cards_dir() -> Path | None:
    """The package's bundled cards (``gisnoise/data/cards``), seeded into a new card store."""
    from gisnoise.data import data_path

    p = data_path("cards")
    return p if p.is_dir() else None


class Settings(BaseSettings):
    """Settings of one service instance (see the module docstring for the variables)."""

    model_config = SettingsConfigDict(env_prefix="GISNOISE_", extra="ignore")

    data_dir: Path = Field(default=Path("gisnoise-data"), description="Card store, job database, job files.")
    api_keys: Annotated[list[str], NoDecode] = Field(default_factory=list,
                                                     description="Keys accepted in X-API-Key for writes.")
    workers: int = Field(default=1, ge=1, le=64, description="Job worker threads.")
    max_request_bytes: int = Field(default=20_000_000, ge=1024, description="Largest request body, bytes.")
    max_upload_bytes: int = Field(default=500_000_000, ge=1024, description="Largest campaign zip, bytes.")
    max_unzipped_bytes: int = Field(default=2_000_000_000, ge=1024, description="Largest unzipped campaign, bytes.")
    max_cells: int = Field(default=25_000_000, ge=1, description="Largest grid, cells.")
    sync_work_limit: float = Field(default=2e8, ge=0,
                                   description="cells x samples above which a contour request becomes a job.")
    max_trajectory_samples: int = Field(default=200_000, ge=2, description="Longest trajectory, samples.")
    max_work: float = Field(default=5e11, gt=0, description="Largest map, cells x time steps (direct or job).")
    seed_cards_dir: Path | None = Field(default_factory=default_seed_cards_dir,
                                        description="Cards copied into an empty store at start-up.")
    tile_url: str = Field(default="https://tile.openstreetmap.org/{z}/{x}/{y}.png",
                          description="Basemap tiles of the web page (an XYZ URL, also a local or self-hosted "
                                      "source); empty for none.")
    tile_attribution: str = Field(default="&copy; OpenStreetMap contributors",
                                  description="Credit shown with the basemap tiles of tile_url once they load.")

    basemap: Path | None = Field(default=None, description="MBTiles or PMTiles file of raster tiles served at /basemap/{z}/{x}/{y} "
                                                            "as the web page's basemap (offline); overrides tile_url.")

    @field_validator("api_keys", mode="before")
    @classmethod
    def _split_keys(cls, v: object) -> object:
        if isinstance(v, str):
            return [k.strip() for k in v.split(",") if k.strip()]
        return v

    @field_validator("seed_cards_dir", "basemap", mode="before")
    @classmethod
    def _empty_is_none(cls, v: object) -> object:
        return None if v == "" else v

    @property
    def cards_dir(self) -> Path:
        return self.data_dir / "cards"

    @property
    def jobs_dir(self) -> Path:
        return self.data_dir / "jobs"

    @property
    def db_path(self) -> Path:
        return self.data_dir / "jobs.sqlite3"


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    """The settings of this process, read once from the environment."""
    return Settings()
