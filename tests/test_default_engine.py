"""`gisnoise contour` with default options runs the fast engine, with --uncertainty too; it agrees with the NumPy engine."""

import json
from pathlib import Path

import numpy as np
import pytest
import rasterio
from click.testing import CliRunner

pytest.importorskip("numba")

from gisnoise.cli.main import cli  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
ROUTE = ROOT / "gisnoise/data/routes/delivery_route.geojson"
CARDS = [str(ROOT / f"gisnoise/data/cards/demo_{p}.json") for p in ("horizontal", "climb", "sink")]


def _map(out: Path, *extra: str) -> tuple[dict, dict]:
    args = ["contour", str(ROUTE), "--out", str(out), "--resolution", "50", "--margin", "300", *extra]
    for c in CARDS:
        args += ["--card", c]
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 0, res.output
    with rasterio.open(out / "levels.tif") as ds:
        meta = json.loads(ds.tags()["gisnoise"])
        bands = {d: ds.read(i + 1) for i, d in enumerate(ds.descriptions)}
    assert f"engine {meta['engine']}" in res.output  # the command says which engine ran
    return meta, bands


def test_default_is_the_fast_engine_with_or_without_uncertainty(tmp_path):
    meta, fast = _map(tmp_path / "default")
    assert meta["engine"] == "fast"
    meta_u, unc = _map(tmp_path / "uncertainty", "--uncertainty")
    assert meta_u["engine"] == "fast"
    meta_r, ref = _map(tmp_path / "reference", "--uncertainty", "--engine", "numpy")
    assert meta_r["engine"] == "numpy"
    for name in ("LAmax", "LAeq", "SEL", "LAmax_p95", "LAeq_p95"):  # the engines agree within the product's 0.01 dB
        np.testing.assert_allclose(unc[name], ref[name], atol=0.01, err_msg=name)
    for name in ("LAmax", "LAeq", "SEL"):
        np.testing.assert_allclose(fast[name], ref[name], atol=0.01, err_msg=name)
    for name in ("LAmax_std", "LAeq_std", "SEL_std"):
        assert np.nanmax(ref[name]) > 0.1  # a case where the uncertainty shows
        np.testing.assert_allclose(unc[name], ref[name], atol=1e-3, err_msg=name)
