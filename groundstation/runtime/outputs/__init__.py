"""skyfix's own outputs, each module registering its own in :mod:`groundstation.runtime.parts` (kind ``output``):
where a UUV's fixes go (the live service's ``outputs``, the fuser's)."""
