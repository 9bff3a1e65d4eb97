"""The bundled demo cards state the powers of the sample campaign they were fitted on, and the demo route's
power model is physical where it leaves them (gisnoise.model.power_range, gisnoise.flight.vehicle).

The campaign's powers are read here from its flight logs with the csv module, not through gisnoise; the
route's lower bound is momentum theory and the drag polar written out.
"""

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from gisnoise.data import card_path, sample_route_path
from gisnoise.flight import GRAVITY, VehicleModel, read_route
from gisnoise.maps import CardSet, check_power_ranges
from gisnoise.model import POWER_RANGE_DEX, load, stated_power_range_w

ROOT = Path(__file__).resolve().parent.parent
CAMPAIGN = ROOT / "sample_data" / "campaign"
# the rows scripts/make_demo_cards fits per card: log phases and the bank limit (deg, None: any bank)
FITTED = {"demo-horizontal": (("horizontal", "transition"), 5.0), "demo-climb": (("climb", "hover"), None),
          "demo-sink": (("sink",), None)}


def _logged_powers(phases, max_bank_deg):
    """Electric power (W) of the campaign's flight-log rows of ``phases`` (and |roll| <= ``max_bank_deg``)."""
    out = []
    for f in sorted((CAMPAIGN / "flights").glob("*.csv")):
        with f.open(newline="") as fh:
            for row in csv.DictReader(fh):
                if row["phase"] in phases and (max_bank_deg is None or abs(float(row["roll"])) <= max_bank_deg):
                    out.append(float(row["power_w"]))
    return np.array(out)


@pytest.mark.skipif(not (CAMPAIGN / "campaign.json").is_file(), reason="no sample campaign in this checkout")
@pytest.mark.parametrize("card_id", sorted(FITTED))
def test_demo_card_states_the_powers_of_the_campaign_rows_it_was_fitted_on(card_id):
    """The fit's rows are microphone samples with the log's power interpolated at emission time, so the range lies
    within the logged powers of the card's rows, and each end within 0.01 dex of the log's (half the tolerance
    the map applies to a stated range: the same powers)."""
    card = load(card_path(card_id))
    phases, bank = FITTED[card_id]
    assert tuple(card.provenance["data"]["phases_fitted"]) == phases
    lo, hi = stated_power_range_w(card)
    logged = _logged_powers(phases, bank)
    assert logged.size > 100
    assert logged.min() <= lo <= hi <= logged.max()
    assert math.log10(lo / logged.min()) < POWER_RANGE_DEX / 2
    assert math.log10(logged.max() / hi) < POWER_RANGE_DEX / 2


@pytest.mark.skipif(not (CAMPAIGN / "campaign.json").is_file(), reason="no sample campaign in this checkout")
def test_demo_card_ranges_equal_the_fitted_rows_read_through_the_campaign():
    """The rows make_demo_cards selects (usable rows of the card's phases, straight flight for the horizontal card):
    their powers' extremes are the stated range, exactly."""
    from gisnoise.identify.fit import usable_rows
    from gisnoise.measure import read_campaign

    rows = usable_rows(read_campaign(CAMPAIGN).samples(), None)
    for card_id, (phases, bank) in FITTED.items():
        m = np.isin(rows.phase, phases)
        if bank is not None:
            m &= np.abs(rows.roll) <= bank
        pw = rows.power_w[m]
        card = load(card_path(card_id))
        assert card.statistics["n_samples"] == int(m.sum())
        assert stated_power_range_w(card) == (float(pw.min()), float(pw.max()))


def _rotor_induced_w(veh, thrust_n):
    """Momentum theory: ideal induced power T^1.5 / sqrt(2 rho A), over figure of merit and motor efficiency (W)."""
    ideal = thrust_n ** 1.5 / math.sqrt(2.0 * veh.air_density_kg_m3 * veh.rotor_disk_area_m2)
    return ideal / veh.figure_of_merit / veh.motor_efficiency


def test_route_power_never_drops_below_holding_its_rotor_borne_weight():
    """Every forward-flight sample of the demo route draws at least the systems power plus the rotors' induced
    power for the share of the weight the wing does not carry, (1 - (v / v_transition)^2) W; the wing's share is
    paid by drag, which the vehicle's kinetic energy may pay while it slows (next test).  Within 0.2 %: the
    samples' power and airspeed are each interpolated in time from the route's profile in path length (0.15 % at
    0.4 m/s, the end of the back-transition)."""
    veh = VehicleModel(mass_kg=35.0, cruise_speed_m_s=25.0, figure_of_merit=0.47)     # the route file's vehicle
    tr = read_route(sample_route_path()).trajectory
    m = tr.flying & np.isin(tr.phase, ("horizontal", "transition"))
    assert m.sum() > 100
    f = np.clip((tr.airspeed_m_s[m] / veh.transition_speed_m_s) ** 2, 0.0, 1.0)
    floor = veh.systems_power_w + _rotor_induced_w(veh, (1.0 - f) * veh.mass_kg * GRAVITY)
    assert np.all(tr.power_w[m] >= floor * (1 - 2e-3))
    slow = m & (tr.power_w < 2000.0)     # below the horizontal card's range: slowing down, the wing unloading
    assert slow.any() and np.all(tr.airspeed_m_s[slow] < veh.cruise_speed_m_s)


def test_wing_borne_deceleration_draws_only_the_systems_power_when_kinetic_power_pays_the_drag():
    """Energy balance of the wing-borne demo vehicle slowing at the route's 1.5 m/s^2 from 24 m/s in a 0.5 m/s
    descent: drag D = q S (CD0 + CL^2 / (pi e AR)) with CL = W / (q S) costs D v = 1.19 kW, the kinetic energy
    gives m a v = 1.26 kW and the descent W w = 0.17 kW, so the pusher idles and only the systems draw power
    (150 W): the demo route's 150 W samples, not a weight term lost.  Slowing at 0.5 m/s^2 needs thrust."""
    veh = VehicleModel()
    v, w, w_n = 24.0, -0.5, veh.mass_kg * GRAVITY
    qs = 0.5 * veh.air_density_kg_m3 * v * v * veh.wing_area_m2
    cl = w_n / qs
    drag = qs * (veh.cd0 + cl ** 2 / (math.pi * veh.oswald_efficiency * veh.aspect_ratio))
    for a in (-1.5, -0.5):
        shaft = drag * v + veh.mass_kg * a * v + w_n * w
        expect = max(shaft, 0.0) / veh.propulsive_efficiency + veh.systems_power_w
        assert float(veh.power_w(v, w, 0.0, a, 1.0)) == pytest.approx(expect, rel=1e-9)
    assert drag * v == pytest.approx(1193.2, abs=0.1) and veh.mass_kg * 1.5 * v == pytest.approx(1260.0)
    assert float(veh.power_w(v, w, 0.0, -1.5, 1.0)) == veh.systems_power_w


def test_demo_route_flies_the_campaign_vehicle_and_warns_only_where_it_slows_down():
    """The route's vehicle is the sample campaign's: it hovers at 2.6 x 3000 W = 7.8 kW (the scenario's default
    ``hover_w``), which momentum theory gives the route's 35 kg vehicle with a figure of merit of 0.47 (the route
    file states it).  So the climb and sink cards are flown within the powers they were fitted at; the horizontal
    card serves the slow-down and the 15 m/s approach before the landing below 2.25 kW (previous tests), where the
    campaign flew at steady speeds: the map says so for that card alone."""
    veh = VehicleModel(mass_kg=35.0, cruise_speed_m_s=25.0, figure_of_merit=0.47)     # the route file's vehicle
    hover = veh.systems_power_w + _rotor_induced_w(veh, veh.mass_kg * GRAVITY)
    assert hover == pytest.approx(2.6 * 3000.0, rel=1e-3)
    cards = {c: load(card_path(c)) for c in FITTED}
    tr = read_route(sample_route_path()).trajectory
    warnings, meta = check_power_ranges(tr, CardSet(list(cards.values())))
    assert sorted(meta) == ["demo-horizontal"] and len(warnings) == 1
    tol = 10.0 ** POWER_RANGE_DEX
    served = {"demo-horizontal": ("horizontal", "transition"), "demo-climb": ("climb", "hover"), "demo-sink": ("sink",)}
    for cid, phases in served.items():
        pw = tr.power_w[tr.flying & np.isin(tr.phase, phases)]
        lo, hi = stated_power_range_w(cards[cid])
        outside = int(np.sum((pw < lo / tol) | (pw > hi * tol)))
        if cid != "demo-horizontal":
            assert outside == 0
            continue
        assert meta[cid]["used_w"] == [pw.min(), pw.max()] and meta[cid]["samples"] == outside
        slow = (pw < lo / tol)
        assert outside == int(slow.sum()) > 0      # below the range only: slowing down, the wing unloading
        assert warnings[0].endswith(f"card {cid!r} is used at {pw.min():.4g}-{pw.max():.4g} W: {outside} "
                                    f"flying sample(s) outside the {lo:.4g}-{hi:.4g} W it was fitted at, where its "
                                    "power term extrapolates")
