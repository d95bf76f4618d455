"""A session on disk (format version 1): ``read`` (the whole directory), ``tlog`` (uav.tlog), ``depth``
(depth.jsonl), ``positions`` (positions.csv). Written by the live recorder
(:mod:`groundstation.live.sinks.recorder`) and by ``skyfix sim``."""


class SessionError(ValueError):
    """A session that cannot be processed; the message is one line."""
