"""The tests in inside/ run in QGIS's own Python (see test_qgis_plugin.py), never in the project's."""

import os

collect_ignore = [] if os.environ.get("GISNOISE_INSIDE_QGIS") == "1" else ["inside"]
