import pytest

from aias_augment.assets.bank.taxonomy import _parse, load_taxonomy


@pytest.mark.parametrize(
    "name, tags, src, expected",
    [
        ("Cone", (), "Miscellaneous", "traffic_cone"),
        ("Sitting female", ("Human",), "Characters", "person"),
        ("Bulldog", (), "Characters", "dog"),
        ("Rocking horse", (), "Living room", "furniture"),  # whole-name match: not a horse
        ("Roasted chicken", (), "Kitchen", "kitchenware"),  # not a bird
        ("Motorbike", ("Outdoor", "Swing"), "Exterior", "outdoor_object"),  # a children's swing, excluded by tag
        ("Yamaha YZR R6", ("Motorbike",), "Vehicles", "motorcycle"),
        ("Something odd", (), "", "other"),
    ],
)
def test_classify(name, tags, src, expected):
    assert load_taxonomy().classify(name, tags, src) == expected


def test_strict_loading():
    with pytest.raises(KeyError, match="unknown"):
        _parse({"categories": {}, "fallback": "other", "extra": 1}, "t")
    with pytest.raises(ValueError, match="fallback"):
        _parse({"categories": {"a": {"height_range_m": [1, 2]}}, "fallback": "other"}, "t")
    with pytest.raises(ValueError, match="bad pattern"):
        _parse({"categories": {"other": {"height_range_m": [1, 2], "names": ["("]}}, "fallback": "other"}, "t")
    with pytest.raises(ValueError, match="height_range_m"):
        _parse({"categories": {"other": {"height_range_m": [2, 1]}}, "fallback": "other"}, "t")
    with pytest.raises(KeyError, match="colour"):
        _parse({"categories": {"other": {"height_range_m": [1, 2], "colour": "red"}}, "fallback": "other"}, "t")
