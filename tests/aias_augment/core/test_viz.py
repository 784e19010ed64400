import numpy as np
import pytest

from aias_augment.core.viz import contact_sheet, draw_boxes


def test_contact_sheet_rows_fill_the_width_at_one_height():
    """Justified rows: a row of images of different aspects is scaled to one height so that their widths plus the
    gaps are the sheet's width; each tile keeps its aspect; the last row keeps the nominal height."""
    ims = [
        np.full((h, w, 3), v, np.uint8) for h, w, v in ((100, 300, 10), (300, 300, 20), (50, 300, 30), (150, 300, 40))
    ]
    sheet = contact_sheet(ims, cols=2, cell_width=300, gap_px=4, background=235)
    # row 1: aspects 3 and 1 -> height h with 3h + h + 4 = 600 -> h = 149; row 2: aspect 6 alone reaches the width
    # (6 x 180 >= 600): h = 600 / 6 = 100; row 3: aspect 2, the last, nominal height 0.6 x 300 = 180
    assert sheet.shape == (149 + 4 + 100 + 4 + 180, 600, 3)
    assert sheet[0, 0, 0] == 10 and sheet[0, 599, 0] == 20  # both tiles reach the edges of row 1
    assert (sheet[:149, :447, 0] == 10).all() and (sheet[:149, 447:451] == 235).all()  # 3 x 149 wide, then the gap
    assert (sheet[:149, 451:, 0] == 20).all()  # the square tile: 149 x 149
    assert (sheet[153:253, :, 0] == 30).all()  # the wide image fills row 2
    last = sheet[257:]
    assert (last[:, :360, 0] == 40).all() and (last[:, 364:, 0] == 235).all()  # 2 x 180 wide, the rest background


def test_draw_boxes_copies_and_colours_inserted_green():
    img = np.zeros((50, 50, 3), np.uint8)
    out = draw_boxes(img, [[10, 10, 20, 20]], ["cone"], [True])
    assert img.max() == 0 and tuple(out[10, 15]) == (40, 220, 40)
    with pytest.raises(ValueError):
        contact_sheet([])
