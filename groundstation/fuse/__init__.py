"""``skyfix fuse``: several drones over one UUV (:mod:`.service`, the decisions in :mod:`.fuser`)."""
