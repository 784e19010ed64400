import numpy as np
import pytest

from aias_augment.apply.harmonize.metrics import fmse, mse, psnr


def test_known_errors():
    a = np.zeros((4, 5, 3), np.uint8)
    b = a.copy()
    b[0, :2] = 10  # 2 pixels x 3 channels, error 10
    mask = np.zeros((4, 5), np.float32)
    mask[0, :4] = 1  # 4 foreground pixels, 2 of them wrong
    assert mse(b, a) == pytest.approx(6 * 100 / 60)
    assert fmse(b, a, mask) == pytest.approx(6 * 100 / 12)
    assert psnr(b, a) == pytest.approx(10 * np.log10(255**2 / 10.0))
    assert psnr(a, a) == float("inf")
    assert fmse(b, a, np.zeros((4, 5))) == 0.0


def test_shape_mismatch_raises():
    with pytest.raises(ValueError):
        mse(np.zeros((4, 5, 3)), np.zeros((4, 6, 3)))
    with pytest.raises(ValueError):
        fmse(np.zeros((4, 5, 3)), np.zeros((4, 5, 3)), np.zeros((5, 4)))
