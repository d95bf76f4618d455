"""Health outputs over real Zenoh: the 1 Hz status JSON and the liveliness token."""

from __future__ import annotations

import asyncio
import json
import socket
import time

from live_helpers import free_port, until

from groundstation.runtime.zenoh_fix import ZenohStatus
from groundstation.runtime.zenoh_session import open_session


def test_status_and_liveliness(caplog):
    """A status that does not fit its model (this one has no depth, a uav section of the wrong shape, an unknown key)
    is still published, and each misfit is logged once, naming the field, however often it is published."""
    ep = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    service, watcher = open_session(listen=[ep]), open_session(connect=[ep])
    got = []
    sub = watcher.declare_subscriber(
        "skyfix/status",
        lambda s: got.append(
            (str(s.encoding), s.timestamp is not None, json.loads(s.payload.to_string()))
        ),
    )
    calls = []

    def status(now):
        calls.append(now)
        return {"uav": {"age_s": {"ATTITUDE": 0.02}}, "n": len(calls)}

    alive = {}
    sink = ZenohStatus(service, "skyfix/status", "skyfix/alive", status, 0.2)

    def tokens(when: str) -> list[str]:
        """The liveliness tokens the watcher sees now (a query: what a monitor asks)."""
        replies = watcher.liveliness().get("skyfix/**", timeout=1.0)
        alive[when] = [str(r.ok.key_expr) for r in replies]
        return alive[when]

    async def scenario():
        task = asyncio.create_task(sink.run())
        try:
            await until(lambda: len(got) >= 3, 30.0, lambda: f"3 statuses, got {len(got)}")
            await until(lambda: tokens("during"), 30.0, "the token")
        finally:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
        await until(lambda: not tokens("after"), 30.0, "the token gone")

    try:
        asyncio.run(scenario())
    finally:
        sub.undeclare()
        watcher.close()
        service.close()
    assert alive["during"] == ["skyfix/alive"] and alive["after"] == []
    assert len(got) >= 3
    assert all(enc == "application/json" and stamped for enc, stamped, _ in got)
    assert (
        got[-1][2]["uav"]["age_s"]["ATTITUDE"] == 0.02 and abs(got[-1][2]["t"] - time.time()) < 2.0
    )
    assert sink.invalid == len(calls) >= 3
    misfits = [
        r.getMessage() for r in caplog.records if "does not fit its schema" in r.getMessage()
    ]
    assert len(misfits) == len(set(misfits)) and any(
        m.startswith("status: depth does not fit") for m in misfits
    )
    assert any(m.startswith("status: n = 1 ") for m in misfits), misfits
