import numpy as np
import pytest

from agent.core.perception.segmentation import (
    ORANGE,
    OrangeRange,
    check_image,
    extract_tuples,
    orange_mask,
)
from tests.perception.synth import canvas, draw_nao


def test_orange_range_of_the_paper() -> None:
    img = canvas()
    img[10:60, 10:60] = (0, 60, 255)  # orange, H ≈ 7
    img[100:150, 100:150] = (0, 0, 255)  # pure red, H = 0: outside [2, 10]
    img[200:250, 200:250] = (0, 255, 255)  # yellow, H = 30
    img[300:350, 300:350] = (60, 100, 140)  # brownish, S too low
    m = orange_mask(img)
    assert m[35, 35] == 255
    assert m[125, 125] == 0 and m[225, 225] == 0 and m[325, 325] == 0
    assert set(np.unique(m)) <= {0, 255}


def test_opening_removes_speckle_and_tuples_are_sorted() -> None:
    img = canvas()
    draw_nao(img, 320, 200, 0.8, 0.0)
    img[5, 5] = (0, 60, 255)  # one-pixel noise
    _, tuples = extract_tuples(orange_mask(img))
    assert len(tuples) == 3
    xs = [t.box[0] for t in tuples]
    assert xs == sorted(xs)
    head = tuples[1]
    assert head.cy < tuples[0].cy and head.cy < tuples[2].cy  # head cap above shoulders


def test_min_area_filters() -> None:
    m = np.zeros((100, 100), np.uint8)
    m[10:13, 10:13] = 255  # 9 px
    m[50:60, 50:60] = 255  # 100 px
    assert len(extract_tuples(m, min_area=12)[1]) == 1
    assert len(extract_tuples(m, min_area=1)[1]) == 2


@pytest.mark.parametrize(
    ("bad", "msg"),
    [
        ([[1, 2, 3]], "numpy array"),
        (np.zeros((0, 0, 3), np.uint8), "empty"),
        (np.zeros((100, 100), np.uint8), r"\(h, w, 3\)"),
        (np.zeros((100, 100, 4), np.uint8), r"\(h, w, 3\)"),
        (np.zeros((100, 100, 3), np.float32), "uint8"),
        (np.zeros((8, 100, 3), np.uint8), "too small"),
    ],
)
def test_check_image_rejects(bad: object, msg: str) -> None:
    with pytest.raises(ValueError, match=msg):
        check_image(bad)


def test_bad_parameters() -> None:
    img = canvas()
    with pytest.raises(ValueError, match="blur"):
        orange_mask(img, blur=4)
    with pytest.raises(ValueError, match="2-D"):
        extract_tuples(np.zeros((0,), np.uint8))
    with pytest.raises(ValueError, match="min_area"):
        extract_tuples(np.zeros((10, 10), np.uint8), min_area=0)


def test_an_orange_range_of_its_own_and_one_that_wraps_through_red() -> None:
    img = canvas()
    img[10:60, 10:60] = (0, 60, 255)  # orange, H ≈ 7
    img[100:150, 100:150] = (40, 0, 255)  # red-magenta, H ≈ 175
    img[200:250, 200:250] = (0, 0, 255)  # pure red, H = 0
    red = OrangeRange((170, 150, 50), (3, 255, 255))
    assert red.wraps and not ORANGE.wraps
    m = orange_mask(img, orange=red)
    assert m[125, 125] == 255 and m[225, 225] == 255 and m[35, 35] == 0
    assert OrangeRange.from_dict(red.to_dict()) == red
    assert orange_mask(img, orange=ORANGE)[35, 35] == 255


@pytest.mark.parametrize(
    ("low", "high", "why"),
    [
        ((2, 170, 50), (10, 255), "three ints"),
        ((2, 170, 50), (180, 255, 255), "hue"),
        ((2, 200, 50), (10, 100, 255), "S and V"),
        ((2.5, 170, 50), (10, 255, 255), "three ints"),
    ],
)
def test_a_bad_orange_range_says_why(low: tuple, high: tuple, why: str) -> None:
    with pytest.raises(ValueError, match=why):
        OrangeRange(low, high)


def test_an_orange_range_from_a_bad_document_says_what_it_expects() -> None:
    with pytest.raises(ValueError, match="hsv_low"):
        OrangeRange.from_dict({"low": [1, 2, 3]})
    with pytest.raises(ValueError, match="lists"):
        OrangeRange.from_dict({"hsv_low": "2,170,50", "hsv_high": [10, 255, 255]})
