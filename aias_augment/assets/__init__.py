"""The objects to insert: mesh assets in the canonical object frame (:mod:`.asset`) and the asset bank
(:mod:`.bank`: catalogues, importers, procedural families, variety, assets lifted from labelled instances)."""
