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
