"""The fast engine's property tests: random effect extensions of cards and the comparison with the NumPy engine.

Shared by ``tests/test_fastkernel.py`` (flight effects) and ``tests/test_fast_receiver_terms.py``
(receiver-dependent terms): the same draws of each effect's parameters, and one rule for what
"the fast engine equals the NumPy engine" means, with and without an audibility floor.
"""

import numpy as np
from hypothesis import strategies as st

from gisnoise.flight import Trajectory
from gisnoise.model import ModelCard

TOL_DB = 0.01
"""The engines agree within this, dB (the fast engine's float32 tables)."""

EFFECT_DRAWS = {
    "bank_angle": lambda draw: dict(k_bank=draw(st.floats(-5.0, 10.0))),
    "rpm": lambda draw: dict(k_rpm=draw(st.floats(-3.0, 3.0)), rpm_ref=draw(st.floats(2500.0, 5000.0))),
    "atmospheric_absorption": lambda draw: dict(a_abs=draw(st.floats(0.0, 60.0))),
    "wind": lambda draw: dict(w_east=draw(st.floats(-5.0, 5.0)), w_north=draw(st.floats(-5.0, 5.0))),
    "doppler": lambda draw: dict(q_doppler=draw(st.floats(0.0, 6.0))),
    "ground_reflection": lambda draw: dict(r_ground=draw(st.floats(0.0, 1.0)),
                                           f_ground=draw(st.floats(20.0, 8000.0))),
}
"""Per effect, a draw of its parameters within their physical range."""


def with_rpm(draw, traj, t=None):
    """``traj`` with a drawn propeller speed per sample (2000-6000 rpm), retimed to ``t`` when given."""
    n = len(traj)
    rpm = np.array(draw(st.lists(st.floats(2000.0, 6000.0), min_size=n, max_size=n)))
    return Trajectory(t=traj.t if t is None else t, lat=traj.lat, lon=traj.lon, h=traj.h, roll=traj.roll,
                      pitch=traj.pitch, yaw=traj.yaw, power_w=traj.power_w, phase=traj.phase, rpm=rpm)


def extended_cards(draw, cards, chain):
    """Each card extended by ``chain`` (``"+a+b"``) with the effects' parameters drawn per card."""
    out = []
    for c in cards:
        p = dict(c.parameters)
        for effect in chain.strip("+").split("+"):
            p.update(EFFECT_DRAWS[effect](draw))
        out.append(ModelCard(id=c.id + chain, vehicle="test", phase=c.phase, ansatz=c.ansatz + chain,
                             parameters=p, reference_power_w=c.reference_power_w))
    return out


def floor_across(ref, floor_q):
    """A floor (dB) across the NumPy map's LAmax range at quantile-like ``floor_q`` (None: no floor), so that
    some cells may fall below it."""
    if floor_q is None:
        return None
    lo, hi = np.nanmin(ref.bands["LAmax"]), np.nanmax(ref.bands["LAmax"])
    return float(lo + floor_q * (hi - lo + 30.0) - 15.0)


def assert_fast_equals_numpy(ref, fast, floor=None, snapshot=False):
    """The fast map ``fast`` equals the NumPy map ``ref`` within :data:`TOL_DB` in LAmax, LAeq, SEL (and the
    snapshot band ``LA@...``): the same cells without value, except cells the fast engine skipped, which
    must lie below ``floor`` in the NumPy map."""
    assert fast.metadata["engine"] == "fast"
    skipped = np.isnan(fast.bands["LAmax"]) & np.isfinite(ref.bands["LAmax"])
    if skipped.any():  # skipped cells are certainly below the floor
        assert floor is not None and np.all(ref.bands["LAmax"][skipped] < floor)
    for name in ("LAmax", "LAeq", "SEL"):
        a, b = ref.bands[name][~skipped], fast.bands[name][~skipped]
        assert np.array_equal(np.isnan(a), np.isnan(b)), name
        assert np.max(np.abs(a - b), initial=0.0, where=np.isfinite(a)) <= TOL_DB, name
    if not snapshot:
        return
    name = next(k for k in ref.bands if k.startswith("LA@"))
    a, b = ref.bands[name], fast.bands[name]
    below = np.isnan(b) & np.isfinite(a)  # at the snapshot the fast engine leaves out what lies below the floor
    if floor is None:
        assert not below.any(), name
    else:
        assert np.all(a[below] < floor), name
    assert not (np.isnan(a) & np.isfinite(b)).any(), name  # no value in the NumPy map: none in the fast one
    both = np.isfinite(a) & np.isfinite(b)
    assert np.max(np.abs(a[both] - b[both]), initial=0.0) <= TOL_DB, name
