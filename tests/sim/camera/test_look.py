"""Looks of the world parsed and checked (sim/camera/look.py): a test per error branch, the
presets, and the SPEC text round trip."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.camera.look import AE_TARGET, PRESETS, RANGES, Look
from sim.physics.nao_model import ORANGE


def test_default_and_empty_specs_are_the_default_look() -> None:
    for text in ("default", "", " , ", "DEFAULT"):
        look = Look.parse(text)
        assert look == Look() and look.is_default()
        assert not look.recolours() and not look.develops()
    assert str(Look()) == "default"


def test_every_parameter_as_written() -> None:
    look = Look.parse("hue:90, sat:0.5,light:0.7,warm:-0.25,noise:4.5,blur:6,exposure:auto,seed:11")
    assert look == Look(
        hue=90.0, sat=0.5, light=0.7, warm=-0.25, noise=4.5, blur=6, exposure=AE_TARGET, seed=11
    )
    assert Look.parse("exposure:140").exposure == 140.0
    assert Look.parse("exposure:off").exposure is None
    assert Look.parse("exposure:AUTO").exposure == AE_TARGET


def test_presets_apply_and_later_items_override_them() -> None:
    assert Look.parse("teal-caps") == PRESETS["teal-caps"]
    look = Look.parse("dim-warm,noise:0")
    assert look.light == PRESETS["dim-warm"].light and look.noise == 0.0
    for name, preset in PRESETS.items():
        assert Look.parse(name) == preset
        assert Look.parse(str(preset)) == preset


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("sunny", "neither KEY:VALUE nor a preset"),
        ("gamma:2", "unknown key 'gamma'"),
        ("hue:10,hue:20", "hue given twice"),
        ("light:bright", "'bright' is not a number"),
        ("exposure:sometimes", "'sometimes' is not a number"),
        ("blur:2.5", "must be a whole number"),
        ("seed:inf", "must be a whole number"),
        ("hue:181", "outside [-180, 180]"),
        ("sat:1.5", "outside [0, 1]"),
        ("light:0", "outside [0.05, 4]"),
        ("warm:-2", "outside [-1, 1]"),
        ("noise:nan", "outside [0, 64]"),
        ("blur:65", "outside [0, 64]"),
        ("exposure:8", "outside [16, 240]"),
        ("seed:-1", "outside [0, 4.29497e+09]"),
    ],
)
def test_bad_specs_say_which_item_and_why(text: str, reason: str) -> None:
    with pytest.raises(ValueError, match="look") as err:
        Look.parse(text)
    assert reason in str(err.value)


@pytest.mark.parametrize(
    ("fields", "reason"),
    [
        ({"hue": "10"}, "is not a number"),
        ({"light": True}, "is not a number"),
        ({"seed": 1.5}, "must be a whole number"),
        ({"noise": -1.0}, "outside"),
    ],
)
def test_bad_fields_are_refused_on_construction(fields: dict[str, object], reason: str) -> None:
    with pytest.raises(ValueError, match=reason):
        Look(**fields)  # type: ignore[arg-type]


def test_recolour_turns_the_hue_and_keeps_the_default_tuple() -> None:
    assert Look().recolour(ORANGE) is ORANGE
    r, g, b, a = Look(hue=167.0).recolour(ORANGE)
    assert a == ORANGE[3] and r < 0.01 and g > 0.9 and b > 0.7  # teal: green and blue
    grey = Look(sat=0.0).recolour(ORANGE)
    assert grey[0] == grey[1] == grey[2] == pytest.approx(1.0)


def _floats(key: str) -> st.SearchStrategy[float]:
    lo, hi = RANGES[key]
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


looks = st.builds(
    Look,
    hue=_floats("hue"),
    sat=_floats("sat"),
    light=_floats("light"),
    warm=_floats("warm"),
    noise=_floats("noise"),
    blur=st.integers(0, 64),
    exposure=st.none() | _floats("exposure"),
    seed=st.integers(0, 2**32 - 1),
)


@settings(max_examples=300, deadline=None)
@given(looks)
def test_a_look_written_as_spec_parses_back_to_itself(look: Look) -> None:
    text = str(look)
    assert Look.parse(text) == look
    assert (text == "default") == look.is_default()
    assert all(math.isfinite(float(v)) for v in (look.hue, look.light))
