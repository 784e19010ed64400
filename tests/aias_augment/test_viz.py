import numpy as np
import pytest

from aias_augment.viz import contact_sheet, draw_boxes


def test_contact_sheet_rows_are_as_tall_as_their_tallest_image():
    ims = [np.full((h, 300, 3), 1, np.uint8) for h in (100, 300, 50, 20, 10)]
    sheet = contact_sheet(ims, cols=2, cell_width=300)
    assert sheet.shape == (300 + 50 + 10, 600, 3)
    assert sheet[:300, 300:].min() == 1 and sheet[100:300, :300].max() == 0  # padding under the shorter image


def test_draw_boxes_copies_and_colours_inserted_green():
    img = np.zeros((50, 50, 3), np.uint8)
    out = draw_boxes(img, [[10, 10, 20, 20]], ["cone"], [True])
    assert img.max() == 0 and tuple(out[10, 15]) == (40, 220, 40)
    with pytest.raises(ValueError):
        contact_sheet([])
