"""The layer stages, one module each with a ``STAGE`` (see :mod:`aias_augment.apply.layers`): a new stage is a new
module here, a field of :class:`~aias_augment.pipeline.config.InsertionConfig` that switches it and, where a preset
should use it, a line in that preset."""
