"""``gisnoise card show`` and ``gisnoise card plot`` (the paper's Fig. 7 and 9)."""

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from gisnoise.cli.main import cli
from gisnoise.maps import directivity_grid
from gisnoise.model import cards

ROOT = Path(__file__).resolve().parents[1]
PUBLISHED_H = ROOT / "gisnoise" / "data" / "cards" / "published_horizontal.json"
DEMO_H = ROOT / "gisnoise" / "data" / "cards" / "demo_horizontal.json"


def run(*args):
    return CliRunner().invoke(cli, ["-q", *args], catch_exceptions=False)


def test_card_show_lists_parameters_and_the_peak_azimuth():
    r = run("card", "show", str(PUBLISHED_H))
    assert r.exit_code == 0, r.output
    assert "published-horizontal" in r.output and "p3 = -0.28" in r.output
    assert "(no covariance)" in r.output
    assert "max at azimuth 74 deg" in r.output  # SPEC 1: p3 + 90 deg at P_el = 1.1


def test_card_show_json_round_trips():
    r = run("card", "show", str(DEMO_H), "--json")
    assert r.exit_code == 0
    assert cards.loads(r.output) == cards.load(DEMO_H)


def test_card_show_standard_deviations_from_the_covariance(tmp_path):
    card = cards.load(PUBLISHED_H)
    std = np.array([1.0, 0.01, 0.02, 0.03, 0.04, 0.05, 0.5])
    fitted = cards.with_parameters(card, card.p, covariance=tuple(map(tuple, np.diag(std ** 2))))
    path = cards.save(fitted, tmp_path / "c.json")
    r = run("card", "show", str(path))
    assert "p4 = -0.365 [-]  +- 0.03" in r.output and "(no covariance)" not in r.output


def test_directivity_numbers_peak_at_74_deg_and_fall_towards_below():
    # paper Fig. 7: 30 m, P_el = 1.1, maximum at azimuth p3 + 90 deg = 74 deg
    phi, theta, lvl = directivity_grid(cards.load(PUBLISHED_H), p_el=1.1, distance_m=30.0, n_phi=3601)
    i, j = np.unravel_index(np.argmax(lvl), lvl.shape)
    assert phi[j] == pytest.approx(np.degrees(-0.280) + 90.0, abs=0.1)
    k = int(np.argmin(np.abs(phi - 74.0)))
    assert lvl[theta == 0.0, k] > lvl[theta == -90.0, k]
    # every grid value is Eq. 9 + Eq. 10 as printed (SPEC 1) with Table 1 (horizontal), at the
    # grid's own azimuth / polar angle: the axes are neither swapped, flipped nor shifted
    p1, p2, p3, p4, p5, p6 = 13.409, 0.176, -0.280, -0.365, 1.049, 0.939
    for phi_deg, theta_deg in ((74.0, 0.0), (74.0, -90.0), (-106.0, 30.0), (180.0, -45.0), (0.0, 90.0)):
        f, t = np.radians(phi_deg), np.radians(theta_deg)
        l_dt = p1 * np.log10(1.1) * (1 + p2 * np.sin(f - p3) * (t + np.pi / 2)) * (1 + p4 * np.sin(t - p5))
        l_sp = -p6 * 20 * np.log10(30.0 / 40.0)
        i, j = int(np.argmin(np.abs(theta - theta_deg))), int(np.argmin(np.abs(phi - phi_deg)))
        assert (theta[i], phi[j]) == pytest.approx((theta_deg, phi_deg), abs=1e-9)
        assert lvl[i, j] == pytest.approx(l_dt + l_sp, abs=1e-9), (phi_deg, theta_deg)


def test_card_plot_writes_a_png(tmp_path):
    out = tmp_path / "fig7.png"
    r = run("card", "plot", str(PUBLISHED_H), "--p-el", "1.1", "--out", str(out))
    assert r.exit_code == 0, r.output
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_card_errors_are_one_line(tmp_path):
    r = CliRunner().invoke(cli, ["card", "plot", str(PUBLISHED_H), "--p-el", "-1", "--out", str(tmp_path / "x.png")])
    assert r.exit_code == 2 and "p_el" in r.output and "Traceback" not in r.output
    (tmp_path / "bad.json").write_text('{"schema": "gisnoise/model-card/9"}')
    r = CliRunner().invoke(cli, ["card", "show", str(tmp_path / "bad.json")])
    assert r.exit_code == 2 and "not supported" in r.output
