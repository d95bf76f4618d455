"""The live service's own outputs, each module registering its own in :mod:`groundstation.live.registry` (kind
``output``): where a UUV's fixes go (its ``outputs``)."""
