"""``gisnoise serve``: the web service (FastAPI under uvicorn).

The service lives in the ``api`` package and is imported only when this
command runs, so the core never imports FastAPI.
"""

from __future__ import annotations

import os
from typing import Any

import click

from gisnoise.errors import InputError


@click.command("serve")
@click.option("--host", default="127.0.0.1", show_default=True, help="Address to listen on.")
@click.option("--port", default=8000, show_default=True, type=click.IntRange(0, 65535), help="TCP port.")
@click.option("--data-dir", type=click.Path(file_okay=False), default=None,
              help="Card store and job folder (default: $GISNOISE_DATA_DIR, else ./gisnoise-data).")
@click.option("--workers", type=click.IntRange(1, 64), default=None,
              help="Job worker threads (default: $GISNOISE_WORKERS, else 1).")
@click.option("--log-level", default="info", show_default=True,
              type=click.Choice(["critical", "error", "warning", "info", "debug"]))
@click.option("--basemap", type=click.Path(dir_okay=False), default=None,
              help="MBTiles file or PMTiles archive of raster tiles the web page shows as its basemap, served at /basemap (offline "
                   "maps; default: $GISNOISE_BASEMAP, else the tile URL $GISNOISE_TILE_URL).")
def command(host: str, port: int, data_dir: str | None, workers: int | None, log_level: str,
            basemap: str | None) -> None:
    """Serve model cards, noise maps and fit/diagnose jobs over HTTP.

    \b
    OpenAPI documentation at http://HOST:PORT/docs, the map page at /.
    Settings come from GISNOISE_* environment variables (see gisnoise/service/README.md):
    GISNOISE_DATA_DIR, GISNOISE_API_KEYS (comma-separated; writes then need
    X-API-Key), GISNOISE_WORKERS, GISNOISE_MAX_REQUEST_BYTES, GISNOISE_MAX_CELLS, ...
    """
    try:
        import uvicorn

        from gisnoise.service.app import create_app
        from gisnoise.service.settings import Settings
    except ImportError as exc:
        raise InputError(f"the service needs the 'api' extra (pip install 'gisnoise[api]'): {exc}",
                         field="serve") from None
    if data_dir is not None:
        os.environ["GISNOISE_DATA_DIR"] = data_dir
    if workers is not None:
        os.environ["GISNOISE_WORKERS"] = str(workers)
    if basemap is not None:
        os.environ["GISNOISE_BASEMAP"] = basemap
    try:
        settings = Settings()
    except Exception as exc:  # pydantic's ValidationError: a bad GISNOISE_* variable
        errors: list[dict[str, Any]] = getattr(exc, "errors", lambda: [])()
        if not errors:
            raise
        e = errors[0]
        name = "GISNOISE_" + "_".join(str(x) for x in e.get("loc", ())).upper()
        raise InputError(f"{name}: {e.get('msg')}, got {os.environ.get(name)!r}", field=name) from None
    if settings.basemap is not None:
        from gisnoise.service.basemap import open_basemap

        try:
            open_basemap(settings.basemap)
        except InputError as exc:
            raise InputError(str(exc).replace("basemap:", "--basemap:", 1), field="--basemap") from None
    app = create_app(settings)
    loop, http = http_stack()
    click.echo(f"gisnoise: serving on http://{host}:{port}/ (docs at /docs), data in {settings.data_dir} "
               f"(event loop {loop}, HTTP parser {http})", err=True)
    uvicorn.run(app, host=host, port=port, log_level=log_level, loop=loop, http=http)


def http_stack() -> tuple[str, str]:
    """uvicorn's event loop and HTTP parser: ``uvloop`` and ``httptools`` when installed (the ``api`` extra brings
    them; they answer a route planner's request about 0.5 ms sooner), else ``asyncio`` and ``h11``."""
    try:
        import uvloop  # noqa: F401
        loop = "uvloop"
    except ImportError:
        loop = "asyncio"
    try:
        import httptools  # noqa: F401
        http = "httptools"
    except ImportError:
        http = "h11"
    return loop, http
