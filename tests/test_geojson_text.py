"""The fast GeoJSON writer: the same numbers as json.dumps of the rounded positions."""

import json

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from gisnoise.maps import geojson_text

POS = arrays(np.float64, st.tuples(st.integers(1, 40), st.just(2)),
             elements=st.floats(-180.0, 180.0, allow_nan=False).map(lambda v: round(v, 8)))


@settings(max_examples=80, deadline=None)
@given(POS, POS)
def test_positions_parse_to_the_same_numbers(a, b):
    doc = {"type": "Feature", "properties": {"name": "LAmax 45 dB(A)", "level_max": None},
           "geometry": {"type": "MultiLineString", "coordinates": [a, b]}}
    text = geojson_text(doc)
    plain = {**doc, "geometry": {"type": "MultiLineString", "coordinates": [a.tolist(), b.tolist()]}}
    assert json.loads(text) == plain


def test_signs_and_digits():
    a = np.array([[-179.99999999, 0.0], [-0.5, 9.00000001], [-10.25, 100.0], [5e-8, -5e-8]])
    text = geojson_text({"c": a})
    assert text == ('{"c":[[-179.99999999,0.00000000],[-0.50000000,9.00000001],[-10.25000000,100.00000000],'
                    '[0.00000005,-0.00000005]]}')
    assert json.loads(text)["c"] == a.tolist()


def test_arrays_anywhere_in_the_document_and_other_objects_refused():
    """Arrays inside tuples, lists and dicts at any depth are written as positions; any other object json cannot
    write is refused as json.dumps refuses it."""
    import pytest

    a = np.array([[1.5, 2.25]])
    doc = {"a": (a, [{"b": a}], {"c": (1, None, "x")}), "d": 2.5}
    assert geojson_text(doc) == '{"a":[[[1.50000000,2.25000000]],[{"b":[[1.50000000,2.25000000]]}],{"c":[1,null,"x"]}],"d":2.5}'
    with pytest.raises(TypeError, match="set is not JSON serializable"):
        geojson_text({"a": a, "s": {1}})
