"""The command lines: ``aias-augment`` (:mod:`.augment`, with :mod:`.offline` and :mod:`.clip`), ``aias-demo``,
``aias-assets``, ``aias-scenes``; the run manifest of an output folder (:mod:`.manifest`)."""
