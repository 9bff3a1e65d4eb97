"""Model cards: load, save, validation, schema versions (SPEC section 4)."""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from gisnoise.errors import CardError, SchemaVersionError
from gisnoise.model import cards

ROOT = Path(__file__).resolve().parents[1]
SAMPLE_CARDS = sorted((ROOT / "gisnoise" / "data" / "cards").glob("*.json"))


@pytest.mark.parametrize("path", SAMPLE_CARDS, ids=lambda p: p.name)
def test_sample_cards_load_and_round_trip(path, tmp_path):
    card = cards.load(path)
    assert cards.loads(cards.dumps(card)) == card
    out = cards.save(card, tmp_path / path.name)
    assert cards.load(out) == card
    assert card.p.shape == (card.model.n_params,)


# the paper's Table 1, p1 ... p7, per column (horizontal flight, vertical flight climb and sink)
TABLE_1 = {
    "horizontal": [13.409, 0.176, -0.280, -0.365, 1.049, 0.939, 40.393],
    "climb": [16.726, 0.090, 0.137, -0.151, 0.293, 1.000, 40.162],
    "sink": [12.722, 0.146, 0.085, -0.513, 0.411, 0.800, 40.278],
}


@pytest.mark.parametrize("phase", sorted(TABLE_1))
def test_published_cards_hold_table_1_verbatim(phase):
    card = cards.load(ROOT / "gisnoise" / "data" / "cards" / f"published_{phase}.json")
    assert card.ansatz == "paper" and card.phase == phase
    assert list(card.model.params) == [f"p{i}" for i in range(1, 8)]
    assert [card.parameters[k] for k in card.model.params] == TABLE_1[phase]


def doc():
    return json.loads((ROOT / "gisnoise" / "data" / "cards" / "published_horizontal.json").read_text())


@pytest.mark.parametrize("schema", ["gisnoise/model-card/2", "gisnoise/model-card/x", "other/1", None])
def test_unknown_schema_is_refused(schema):
    d = doc()
    d["schema"] = schema
    with pytest.raises(SchemaVersionError) as exc:
        cards.loads(json.dumps(d))
    assert exc.value.field == "schema"


def test_malformed_json_names_line_and_column(tmp_path):
    p = tmp_path / "c.json"
    p.write_text('{"schema": "gisnoise/model-card/1",\n  "id": }')
    with pytest.raises(CardError, match=r"malformed JSON at line 2 column 9") as exc:
        cards.load(p)
    assert exc.value.field == "json" and str(p) in str(exc.value)


@pytest.mark.parametrize("change, field", [
    (lambda d: d.pop("parameters"), "parameters"),
    (lambda d: d["parameters"].pop("p6"), "parameters"),
    (lambda d: d["parameters"].update(p9=1.0), "parameters"),
    (lambda d: d["parameters"].update(p2="big"), "parameters.p2"),
    (lambda d: d.update(phase="cruise"), "phase"),
    (lambda d: d.update(ansatz="nope"), "ansatz"),
    (lambda d: d.update(reference_power_w=0), "reference_power_w"),
    (lambda d: d.update(covariance=[[1.0, 0.0], [0.0, 1.0]]), "covariance"),
    (lambda d: d.update(covariance=(-np.eye(7)).tolist()), "covariance"),
    (lambda d: d.update(phases="hover"), "phases"),
])
def test_invalid_cards_name_the_field(change, field):
    d = doc()
    change(d)
    with pytest.raises(CardError) as exc:
        cards.from_dict(d)
    assert exc.value.field == field


def test_save_refuses_to_overwrite_when_asked(tmp_path):
    card = cards.load(SAMPLE_CARDS[0])
    p = cards.save(card, tmp_path / "c.json")
    with pytest.raises(CardError, match="refusing to overwrite"):
        cards.save(replace(card, notes="x"), p, overwrite=False)
    assert cards.load(p) == card


def test_missing_card_file(tmp_path):
    with pytest.raises(CardError, match="no such card file") as exc:
        cards.load(tmp_path / "none.json")
    assert exc.value.field == "card"


def test_a_card_with_parameters_near_the_float_limit_is_refused_naming_them(recwarn):
    """Directivity coefficients of 1e40-1e156 (found by the request fuzzer): the levels overflow, and their share of
    the level (Jacobian times parameter) overflows too; the card is refused naming those parameters, with no
    floating-point warning on the way."""
    import warnings

    from gisnoise.model import ModelCard
    from gisnoise.model.plausibility import card_problems

    par = dict(p0=70.0, p1=20.0, p2=-7.888581266818121e40, p3=0.0, p4=9.315563349416767e155,
               p5=3.46778199803437e150, p6=1.0, p7=40.0)
    card = ModelCard(id="x", vehicle="v", phase="horizontal", ansatz="paper-offset", parameters=par,
                     reference_power_w=3000.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        problems = card_problems(card)
    assert len(problems) == 1 and "outside the plausible" in problems[0]
    named = problems[0].split("driven by ")[1]
    assert any(f"{k} =" in named for k in ("p2", "p4", "p5"))
    assert not any(f"{k} =" in named for k in ("p0", "p1", "p3", "p6", "p7"))
