"""The output ``zenoh``: each fix message (``skyfix.fix/1``) on the UUV's ``fix_key``
(:class:`~groundstation.runtime.zenoh_fix.ZenohFixSink`)."""

from __future__ import annotations

from groundstation.runtime.parts import OutputInput, register
from groundstation.runtime.zenoh_fix import ZenohFixSink


@register("output", "zenoh", "each fix as JSON on Zenoh (--fix-key)")
def build(out: OutputInput) -> ZenohFixSink:
    return ZenohFixSink(out.session, out.options.fix_key)
