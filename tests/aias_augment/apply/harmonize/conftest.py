import cv2
import numpy as np
import pytest

from aias_augment.core.config import data_root


@pytest.fixture(scope="session")
def street_rgb() -> np.ndarray:
    """A real KITTI colour frame (sunny street), cropped to 320x240 to keep tests fast."""
    path = data_root() / "kitti06_color_snippet" / "kitti06-12-color.png"
    if not path.exists():
        pytest.skip(f"real data missing: {path}")
    img = cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)
    return np.ascontiguousarray(img[120:360, 400:720])


@pytest.fixture(autouse=True)
def _one_torch_thread():
    """The CI machine has 2 shared cores; one intra-op thread avoids spin-waiting (3x faster measured here)."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
