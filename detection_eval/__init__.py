"""detection_eval: a compact YOLOX-style detector (PAFPN neck, decoupled anchor-free head, SimOTA) for measuring
what inserted objects do to detection mAP. CPU-friendly; device-agnostic."""
