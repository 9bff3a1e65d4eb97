"""The plugin from the built zip registers its provider and uses the core it bundles."""

from pathlib import Path

import pytest

pytestmark = pytest.mark.qgis


def test_provider_registered_with_its_algorithms(plugin):
    from qgis.core import QgsApplication

    provider = QgsApplication.processingRegistry().providerById("gisnoise")
    assert provider is not None
    assert provider.name() == "Drone noise (gisnoise)"
    ids = {alg.id() for alg in provider.algorithms()}
    assert {"gisnoise:noisemap", "gisnoise:fitcard", "gisnoise:diagnose", "gisnoise:designlayout"} <= ids
    for alg in provider.algorithms():
        assert alg.shortHelpString() and alg.displayName() and alg.group()


def test_core_comes_from_the_zip(plugin, profile):
    from gisnoise_qgis._core import ensure_core

    gisnoise = ensure_core()
    ext = profile / "profiles" / "default" / "python" / "plugins" / "gisnoise_qgis" / "ext"
    assert Path(gisnoise.__file__).resolve().is_relative_to(ext.resolve())


def test_metadata_is_complete(plugin, profile):
    import configparser

    folder = profile / "profiles" / "default" / "python" / "plugins" / "gisnoise_qgis"
    meta = configparser.ConfigParser()
    meta.read(folder / "metadata.txt", encoding="utf-8")
    general = meta["general"]
    for key in ("name", "qgisMinimumVersion", "description", "about", "version", "author", "email", "tracker",
                "repository", "icon"):
        assert general.get(key, "").strip(), key
    assert general["hasProcessingProvider"] == "yes"
    assert (folder / general["icon"]).is_file()
    import gisnoise

    assert general["version"] == gisnoise.__version__
