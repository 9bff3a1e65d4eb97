"""Every JSON input file (card, scenario, plan, schedule) is refused the same way when unreadable."""

import pytest

from gisnoise.design import load_plan
from gisnoise.errors import CardError, DesignError, InputError, ScenarioError
from gisnoise.model import cards
from gisnoise.ops import load_schedule
from gisnoise.simulate import load_scenario

LOADERS = [(cards.load, CardError, "card"), (load_scenario, ScenarioError, "scenario"),
           (load_plan, DesignError, "plan"), (load_schedule, InputError, "schedule")]


@pytest.mark.parametrize("load, error, what", LOADERS)
def test_missing_unreadable_and_malformed_files_name_the_file(tmp_path, load, error, what):
    with pytest.raises(error, match=f"no such {what} file"):
        load(tmp_path / "absent.json")
    with pytest.raises(error, match=f"{tmp_path}: cannot read {what}"):  # a folder is not a file
        load(tmp_path)
    bad = tmp_path / "bad.json"
    bad.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(error, match=f"cannot read {what}"):
        load(bad)
    broken = tmp_path / "broken.json"
    broken.write_text('{"a": 1,\n "b": }')
    with pytest.raises(error, match="malformed JSON at line 2 column 7"):
        load(broken)


def test_a_byte_order_mark_is_accepted(tmp_path):
    from pathlib import Path

    src = Path(__file__).resolve().parents[1] / "gisnoise/data/cards/published_horizontal.json"
    p = tmp_path / "bom.json"
    p.write_bytes(b"\xef\xbb\xbf" + src.read_bytes())
    assert cards.load(p).parameters["p3"] == -0.280  # paper Table 1
