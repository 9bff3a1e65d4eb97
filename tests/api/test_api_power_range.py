"""POST /contours: a card without power term at another power is 422 naming trajectory.power_w
(gisnoise.model.power_range)."""

from __future__ import annotations

import math


def _flyover_csv(power_w: float) -> str:
    rows = ["t,lat,lon,h,roll,pitch,yaw,power_w,phase"]
    m_per_deg = 111_320.0 * math.cos(math.radians(52.27))
    rows += [f"{t:.1f},52.27,{10.52 + 15.0 * t / m_per_deg:.9f},60,0,0,90,{power_w},horizontal" for t in range(41)]
    return "\n".join(rows) + "\n"


STEADY = {"schema": "gisnoise/model-card/1", "id": "steady", "vehicle": "v", "phase": "horizontal",
          "ansatz": "paper-offset", "covariance": None, "reference_power_w": 3000.0, "reference_distance_m": 40.0,
          "parameters": {"p0": 64.0, "p1": 0.0, "p2": 0.0, "p3": 0.0, "p4": 0.0, "p5": 0.0, "p6": 1.0, "p7": 40.0},
          "statistics": {"power_range_w": [2400.0, 2400.0]},
          "provenance": {"held_parameters": {"p1": "steady power: held at 0"}}}


def test_card_without_power_term_at_another_power_is_422(client):
    req = {"trajectory": {"format": "csv", "text": _flyover_csv(3000.0)}, "cards": [STEADY],
           "grid": {"resolution_m": 20, "margin_m": 200}, "ground_h_m": 0.0}
    r = client.post("/contours", json=req)
    assert r.status_code == 422, r.text
    # the request's field: the trajectory's power (a column here, a log's power_w) (it said 'power_w')
    assert r.json()["field"] == "trajectory.power_w" and "(2400-2400 W" in r.json()["detail"]
    assert "--power-w" not in r.json()["detail"]
    ok = client.post("/contours", json=dict(req, trajectory={"format": "csv", "text": _flyover_csv(2400.0)}))
    assert ok.status_code == 200, ok.text
