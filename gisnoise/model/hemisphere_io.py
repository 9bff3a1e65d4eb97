"""Import of measured hemispheres into hemisphere cards (:mod:`gisnoise.model.hemisphere`).

Two layouts are read:

* **Salford xlsx** (the DroneNoise hemispheres of the University of Salford): one sheet per
  one-third-octave band named ``band_<nominal Hz>`` (``band_20`` .. ``band_20000``), first row
  ``Phi`` then the theta angles (deg), first column the phi angles (deg), cells the band SPL
  (dB) at the radius; ``band_Overall`` and ``SWL_Bands`` are read for the record only.  Needs
  ``openpyxl`` (the extra ``hemisphere``).
* **CSV, long form** (the generic layout; the Salford long form is one case of it): one row
  per band and node with the columns ``band`` (nominal mid-band frequency in Hz; rows whose
  band is ``Overall`` are skipped), ``phi_deg``, ``theta_deg``, a level column ``level_db``
  (or ``spl_db_at_1m``: radius 1 m), optionally ``radius_m`` (one value for the file) and
  ``measured`` (1 measured, 0 filled).  Every band must give every node.

The angles are the table angles of :mod:`gisnoise.model.hemisphere` (Salford convention):
``phi`` along the track, negative ahead of the drone (the hemisphere rows measured while the
drone approached the microphone line), ``theta`` across it, positive to starboard.

**Measured cells.**  A ``measured`` column decides.  Otherwise a cell is measured when
``|theta| <= measured_theta_max`` (deg; the Salford line of 9 microphones spans +-60) and its
phi row is not a constant fill: rows at either end of the table that repeat their inner
neighbour in every band and column are fill (the Salford tool extends the outermost measured
row to the horizon that way); the innermost row of such a run is measured.  A table whose rows
are all equal shows no fill (:func:`fill_rows`): every row counts.

**Checks at import** (each a one-line :class:`~gisnoise.errors.CardError` naming the file and
the field; the card written is one every other command takes):

* the checks of every table that enters the product, the same that reading a card document runs
  (:func:`gisnoise.model.hemisphere.table_problems`): angles in degrees, not radians (an axis of
  more than one angle, all within +-:data:`RADIAN_LIMIT_DEG`, field ``phi_deg`` or ``theta_deg``);
  bands that are nominal one-third-octave frequencies in Hz from :data:`LOWEST_BAND_HZ` on (a
  table in kHz gives 0.02-20 "Hz") with every band between the lowest and the highest (field
  ``band``: the file's band column or ``band_<Hz>`` sheets);
* the rows and columns of a workbook sheet may come in any order (each carries its angle): they
  are sorted; an angle given twice is refused naming the sheet and cells, a blank, text or
  non-finite cell naming its cell (``C7``);
* a CSV's radius: ``spl_db_at_1m`` with a ``radius_m`` other than 1, or a ``radius_m`` argument
  other than the radius the file states, is refused (field ``radius_m``);
* the plausibility guard of the maps and the service (:func:`gisnoise.model.check_card`: radius
  1 m - 1 km, levels at 40 m within -20..160 dB(A)).

A table that does not reach the horizon on every side is taken (the map gives the directions
beyond it the edge values); :func:`import_warnings` says which ranges it lacks.
"""

from __future__ import annotations

import csv
import math
import os
import re
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.acoustics import nominal_frequency
from gisnoise.errors import CardError
from gisnoise.model.hemisphere import (
    HEMISPHERE_ANSATZ,
    LOWEST_BAND_HZ,
    RADIAN_LIMIT_DEG,
    HemisphereCard,
    band_problem,
    table_problems,
)
from gisnoise.model.plausibility import check_card

__all__ = ["LOWEST_BAND_HZ", "RADIAN_LIMIT_DEG", "SALFORD_ATMOSPHERE", "fill_rows", "import_hemisphere",
           "import_warnings", "read_hemisphere_csv", "read_salford_xlsx"]

SALFORD_ATMOSPHERE = {"temperature_c": 25.0, "humidity_pct": 70.0, "pressure_kpa": 101.325}
"""The atmosphere the Salford tool back-propagates with (25 C, 70 % RH, 29.92 inHg)."""

_SALFORD_NAME = re.compile(r"Hem_(?P<site>[A-Za-z]+)_(?P<drone>[A-Za-z0-9]+)_(?P<h>\d+)_F(?P<v>\d+)_")
_DRONES = {"M3": "DJI Matrice 300 RTK", "M2": "DJI Mavic 2 Pro", "3p": "DJI Phantom 3"}


def _err(path: Any, msg: str, fld: str) -> CardError:
    return CardError(f"{path}: {msg}", field=fld)


def _band(path: Any, v: Any) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise _err(path, f"band {v!r} is not a frequency in Hz", "band") from None
    why = band_problem(f)
    if why is not None:
        raise _err(path, f"band {v!r} {why}", "band")
    return float(nominal_frequency(f))


def _cell(col: int, row: int) -> str:
    """Spreadsheet reference of 1-based column and row (``C7``)."""
    name = ""
    while col:
        col, r = divmod(col - 1, 26)
        name = chr(65 + r) + name
    return f"{name}{row}"


def _number(path: Any, sheet: str, v: Any, col: int, row: int, what: str) -> float:
    """The finite number of a workbook cell, else an error naming its sheet and cell."""
    ref = _cell(col, row)
    if v is None or (isinstance(v, str) and not v.strip()):
        raise _err(path, f"sheet {sheet!r}: cell {ref} is blank ({what} expected)", f"sheet {sheet}")
    try:
        if isinstance(v, bool):
            raise TypeError
        x = float(v)
    except (TypeError, ValueError):
        raise _err(path, f"sheet {sheet!r}: cell {ref} holds {v!r}, not a number ({what})", f"sheet {sheet}") from None
    if not math.isfinite(x):
        raise _err(path, f"sheet {sheet!r}: cell {ref} holds {v!r}, not a finite number ({what})", f"sheet {sheet}")
    return x


def _sorted_axis(path: Any, sheet: str, a: np.ndarray, refs: list[str], name: str) -> np.ndarray:
    """The order sorting an axis ascending; an angle given twice is refused naming its cells."""
    order = np.argsort(a, kind="stable")
    same = np.flatnonzero(np.diff(a[order]) == 0)
    if same.size:
        k, m = int(order[same[0]]), int(order[same[0] + 1])
        raise _err(path, f"sheet {sheet!r}: {name} {a[k]:g} deg given twice (cells {refs[k]} and {refs[m]})",
                   f"sheet {sheet}")
    return order


def _read_sheet(path: Any, name: str, ws: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(phi, theta, table)`` of one band sheet, rows and columns sorted by their angles."""
    rows = [(n, r) for n, r in enumerate(ws.iter_rows(values_only=True), start=1)
            if any(v is not None and str(v).strip() for v in r)]
    if not rows or str(rows[0][1][0]).strip().lower() != "phi":
        raise _err(path, f"sheet {name!r}: first cell must be 'Phi'", f"sheet {name}")
    n0, head = rows[0]
    last = max(k for k, v in enumerate(head) if v is not None and str(v).strip())
    if last < 1:
        raise _err(path, f"sheet {name!r}: no theta angles after 'Phi' in row {n0}", f"sheet {name}")
    th = np.array([_number(path, name, head[k], k + 1, n0, "theta angle") for k in range(1, last + 1)])
    ph = np.array([_number(path, name, r[0], 1, n, "phi angle") for n, r in rows[1:]])
    tab = np.array([[_number(path, name, r[k] if k < len(r) else None, k + 1, n, "level in dB")
                     for k in range(1, last + 1)] for n, r in rows[1:]]).reshape(ph.size, th.size)
    if ph.size == 0:
        raise _err(path, f"sheet {name!r}: no phi rows below row {n0}", f"sheet {name}")
    op = _sorted_axis(path, name, ph, [_cell(1, n) for n, _ in rows[1:]], "phi")
    ot = _sorted_axis(path, name, th, [_cell(k + 1, n0) for k in range(1, last + 1)], "theta")
    return ph[op], th[ot], tab[np.ix_(op, ot)]


def read_salford_xlsx(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The tables of a Salford hemisphere workbook: ``phi_deg``, ``theta_deg``, ``bands_hz``, ``levels_db``
    ``(bands, phi, theta)``, ``overall_db`` (``band_Overall`` or None), ``swl_db`` (band -> dB).

    Rows and columns are sorted by their angles (each row and column carries its angle, so any order is
    unambiguous); a blank or non-numeric cell is refused naming its sheet and cell.
    """
    try:
        import openpyxl
    except ImportError:
        raise CardError("reading xlsx hemispheres needs openpyxl (pip install 'gisnoise[hemisphere]'); "
                        "or give the CSV long form", field="file") from None
    try:
        wb = openpyxl.load_workbook(path, read_only=True, data_only=True)
    except Exception as exc:  # noqa: BLE001 - any reader failure is a bad file
        raise _err(path, f"not a readable xlsx workbook ({type(exc).__name__})", "file") from None
    sheets: dict[float, np.ndarray] = {}
    phi = theta = None
    overall = None
    swl: dict[str, float] = {}
    for name in wb.sheetnames:
        if name == "SWL_Bands":
            rows = [r for r in wb[name].iter_rows(values_only=True) if any(v is not None for v in r)]
            for r in rows[1:]:
                if r[0] is not None and r[1] is not None:
                    swl[str(r[0]).removeprefix("band_")] = float(r[1])
            continue
        if not name.startswith("band_"):
            continue
        ph, th, tab = _read_sheet(path, name, wb[name])
        if phi is None:
            phi, theta = ph, th
        elif not (np.array_equal(ph, phi) and theta is not None and np.array_equal(th, theta)):
            raise _err(path, f"sheet {name!r}: angles differ from the first band's", f"sheet {name}")
        tag = name.removeprefix("band_")
        if tag.lower() == "overall":
            overall = tab
        else:
            sheets[_band(path, tag)] = tab
    if not sheets or phi is None:
        raise _err(path, "no band_<Hz> sheets (not a Salford hemisphere workbook?)", "file")
    bands = sorted(sheets)
    return {"phi_deg": phi, "theta_deg": theta, "bands_hz": np.array(bands),
            "levels_db": np.stack([sheets[b] for b in bands]), "overall_db": overall, "swl_db": swl,
            "radius_m": None, "measured": None}


def read_hemisphere_csv(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The tables of a long-form hemisphere CSV (module docstring); keys as :func:`read_salford_xlsx`."""
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            rows = list(csv.DictReader(fh))
    except OSError as exc:
        raise _err(path, f"cannot read ({exc.strerror})", "file") from None
    except (UnicodeDecodeError, csv.Error):
        raise _err(path, "not a text CSV file", "file") from None
    if not rows:
        raise _err(path, "no rows", "file")
    cols = set(rows[0])
    lvl = "level_db" if "level_db" in cols else "spl_db_at_1m" if "spl_db_at_1m" in cols else None
    for c in ("band", "phi_deg", "theta_deg"):
        if c not in cols:
            raise _err(path, f"missing column '{c}' (columns: band, phi_deg, theta_deg, level_db, "
                             "optional radius_m, measured)", c)
    if lvl is None:
        raise _err(path, "missing level column 'level_db' (or 'spl_db_at_1m')", "level_db")
    radius = 1.0 if lvl == "spl_db_at_1m" else None
    vals: dict[tuple[float, float, float], float] = {}
    meas: dict[tuple[float, float], bool] = {}
    radii = set()
    for n, r in enumerate(rows, start=2):
        if str(r["band"]).strip().lower() == "overall":
            continue
        band = _band(path, r["band"])
        try:
            key = (band, float(r["phi_deg"]), float(r["theta_deg"]))
            v = float(r[lvl])
        except (TypeError, ValueError):
            raise _err(path, f"line {n}: non-numeric angle or level", lvl) from None
        if not all(math.isfinite(x) for x in (*key, v)):
            raise _err(path, f"line {n}: non-finite value", lvl)
        for col, a in (("phi_deg", key[1]), ("theta_deg", key[2])):
            if abs(a) > 90.0:
                raise _err(path, f"line {n}: {col} {a:g} lies beyond the horizon (table angles -90..90 deg, 0 "
                                 "straight below)", col)
        if key in vals:
            raise _err(path, f"line {n}: node band {key[0]:g} Hz, phi {key[1]:g}, theta {key[2]:g} given twice", lvl)
        vals[key] = v
        if "radius_m" in cols and r["radius_m"] not in (None, ""):
            try:
                radii.add(float(r["radius_m"]))
            except ValueError:
                raise _err(path, f"line {n}: column 'radius_m' holds {r['radius_m']!r}, not a radius in m",
                           "radius_m") from None
        if "measured" in cols and r["measured"] not in (None, ""):
            m = str(r["measured"]).strip().lower()
            if m not in ("0", "1", "true", "false"):
                raise _err(path, f"line {n}: column 'measured' must be 1 or 0, got {r['measured']!r}", "measured")
            meas[key[1:]] = meas.get(key[1:], False) or m in ("1", "true")
    if not vals:
        raise _err(path, "no band rows (only Overall?); the map needs one-third-octave bands", "band")
    if len(radii) > 1:
        raise _err(path, f"column 'radius_m' must hold one radius, got {sorted(radii)}", "radius_m")
    if radii:
        radius = radii.pop()
        if lvl == "spl_db_at_1m" and radius != 1.0:
            raise _err(path, f"column 'spl_db_at_1m' gives levels at 1 m, column 'radius_m' a radius of {radius:g} m: "
                             "name the level column 'level_db' for levels at another radius", "radius_m")
    bands = sorted({k[0] for k in vals})
    phi = sorted({k[1] for k in vals})
    theta = sorted({k[2] for k in vals})
    tab = np.full((len(bands), len(phi), len(theta)), np.nan)
    ib = {b: i for i, b in enumerate(bands)}
    ip = {p: i for i, p in enumerate(phi)}
    it = {t: i for i, t in enumerate(theta)}
    for (b, p, t), v in vals.items():
        tab[ib[b], ip[p], it[t]] = v
    if np.isnan(tab).any():
        b, p, t = np.argwhere(np.isnan(tab))[0]
        raise _err(path, f"no level for band {bands[b]:g} Hz at phi {phi[p]:g}, theta {theta[t]:g} "
                         "(every band needs every node)", lvl)
    measured = None
    if meas:
        measured = np.array([[meas.get((p, t), False) for t in theta] for p in phi])
    return {"phi_deg": np.array(phi), "theta_deg": np.array(theta), "bands_hz": np.array(bands),
            "levels_db": tab, "overall_db": None, "swl_db": {}, "radius_m": radius, "measured": measured}


def _check_table(path: Any, t: dict[str, Any]) -> None:
    """Refuse a table whose units or bands every card refuses (:func:`~gisnoise.model.hemisphere.table_problems`)."""
    problems = table_problems(t["phi_deg"], t["theta_deg"], t["bands_hz"])
    if problems:
        fld, reason = problems[0]
        if fld == "bands_hz":  # the file's bands: its 'band' column, its band_<Hz> sheets
            raise _err(path, reason, "band")
        raise _err(path, f"{fld}: {reason}", fld)


def import_warnings(card: HemisphereCard) -> list[str]:
    """What a user should know about an imported table (none for the Salford files): the directions of the lower
    hemisphere its angles do not reach, which the map gives the edge values of the table."""
    cov = card.uncovered()
    if not cov["ranges"]:
        return []
    return [f"hemisphere {card.id!r}: the table does not reach the horizon: {', '.join(cov['ranges'])} not "
            f"covered ({100.0 * cov['share']:.0f} % of the lower hemisphere's solid angle); maps give those "
            "directions the table's edge values (counted as filled)"]


def fill_rows(levels_db: np.ndarray) -> np.ndarray:
    """Rows (phi) at the table's ends that repeat their inner neighbour in every band: constant fill.

    The innermost row of each run is the measured one it repeats.  A table whose rows are all equal has no
    such row to tell (the runs from both ends would take each other's, and every row would count as fill):
    none of its rows is fill.

    Examples
    --------
    >>> fill_rows(np.array([[[1.0], [1.0], [2.0], [3.0], [3.0], [3.0]]])).tolist()
    [True, False, False, False, True, True]
    >>> fill_rows(np.full((2, 4, 3), 70.0)).tolist()
    [False, False, False, False]
    """
    n = levels_db.shape[1]
    fill = np.zeros(n, bool)
    i = 0
    while i + 1 < n and np.array_equal(levels_db[:, i], levels_db[:, i + 1]):
        fill[i] = True
        i += 1
    if i == n - 1:  # every row equals its neighbour: no measured row to tell the fill by
        return np.zeros(n, bool)
    i = n - 1
    while i - 1 >= 0 and np.array_equal(levels_db[:, i], levels_db[:, i - 1]):
        fill[i] = True
        i -= 1
    return fill


def import_hemisphere(path: str | os.PathLike[str], *, card_id: str | None = None, vehicle: str | None = None,
                      phase: str = "horizontal", phases: tuple[str, ...] = (), radius_m: float | None = None,
                      atmosphere: dict[str, float] | None = None, measured_theta_max: float | None = 60.0,
                      condition: dict[str, Any] | None = None, reference_power_w: float | None = None
                      ) -> HemisphereCard:
    """A hemisphere card from a Salford xlsx or a long-form CSV (by the file's suffix), checked as the module
    docstring says (:class:`~gisnoise.errors.CardError` naming the file and field; the plausibility guard's
    :class:`~gisnoise.model.ImplausibleCardError`); :func:`import_warnings` gives what it takes but should say.

    ``atmosphere`` (``temperature_c``, ``humidity_pct``, ``pressure_kpa``) is required for
    files not in the Salford layout.  Defaults for the Salford files: radius 1 m, atmosphere :data:`SALFORD_ATMOSPHERE`, vehicle,
    height and speed from the file name (``Hem_<site>_<drone>_<height m>_F<speed m/s>_...``).
    ``reference_power_w``: the electric power of the flight condition, W, if known (the table's
    level does not depend on power; the value is recorded).
    """
    p = Path(path)
    if not p.is_file():
        raise CardError(f"{p}: no such file", field="file")
    suffix = p.suffix.lower()
    if suffix in (".xlsx", ".xlsm"):
        t = read_salford_xlsx(p)
    elif suffix in (".csv", ".txt"):
        t = read_hemisphere_csv(p)
    else:
        raise CardError(f"{p}: unknown hemisphere layout {suffix!r} (give .xlsx or .csv)", field="file")
    _check_table(p, t)
    m = _SALFORD_NAME.match(p.name)
    cond: dict[str, Any] = {}
    if m:
        cond = {"height_m": float(m["h"]), "speed_m_s": float(m["v"])}
        vehicle = vehicle or _DRONES.get(m["drone"], m["drone"])
    if reference_power_w is not None:
        cond["power_w"] = float(reference_power_w)
    cond.update(condition or {})
    salford = m is not None or suffix.startswith(".xls")
    if atmosphere is None and not salford:
        raise CardError(f"{p}: give the atmosphere the table was back-propagated with (temperature, humidity)",
                        field="atmosphere")
    if radius_m is not None and t["radius_m"] is not None and float(radius_m) != float(t["radius_m"]):
        raise CardError(f"{p}: radius_m = {float(radius_m):g} m contradicts the file's radius of {t['radius_m']:g} m",
                        field="radius_m")
    radius = radius_m if radius_m is not None else t["radius_m"] if t["radius_m"] is not None else 1.0
    levels = np.asarray(t["levels_db"], dtype=float)
    if t["measured"] is not None:
        measured = np.asarray(t["measured"], bool)
    else:
        rows_ok = ~fill_rows(levels)
        theta = np.asarray(t["theta_deg"])
        cols_ok = np.ones(theta.size, bool) if measured_theta_max is None else np.abs(theta) <= measured_theta_max
        measured = rows_ok[:, None] & cols_ok[None, :]
    stats: dict[str, Any] = {"measured_cells": int(measured.sum()), "cells": int(measured.size)}
    if t["swl_db"]:
        stats["file_sound_power_db"] = dict(t["swl_db"])
    notes = (f"measured hemisphere imported from {p.name}; table angles: phi along the track "
             "(negative ahead), theta across it (positive starboard); "
             f"{int(measured.sum())} of {measured.size} cells measured, the others filled by the source file")
    card = HemisphereCard(
        id=card_id or p.stem, vehicle=vehicle or "unknown", phase=phase, phases=tuple(phases),
        ansatz=HEMISPHERE_ANSATZ, parameters={}, reference_power_w=float(reference_power_w or 1.0),
        reference_distance_m=float(radius), phi_deg=t["phi_deg"], theta_deg=t["theta_deg"],
        bands_hz=t["bands_hz"], levels_db=levels, measured=measured,
        atmosphere=dict(atmosphere or SALFORD_ATMOSPHERE), condition=cond, statistics=stats,
        provenance={"source_file": p.name, "layout": "salford-xlsx" if suffix.startswith(".xls") else "csv-long"},
        notes=notes)
    check_card(card, source=str(p))  # the guard of maps and service: never write a card they refuse
    return card
