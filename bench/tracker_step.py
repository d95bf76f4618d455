"""The default tracker's per-frame step alone, offline: CPU per UUV-frame, and whether its results are identical
(issue 30).

``skyfix process`` of a session is run once per source tree (``--height-from-size off``: the tracking is the same)
with :meth:`~localizer.tracking.session.TrackingSession.step` recorded: each UUV's session as it was before its first
step, and every step's frame and pose. The steps are then replayed ``--repeats`` times from those states, timed with
the thread's CPU clock (the decoder's threads are not counted); the best replay counts. Each frame's colour is
replayed with it, for the colour check. The results' digest (every step's :class:`~localizer.tracking.TrackResult`)
must be the same for every tree: a change that alters one value shows here. Trees are run in turn, ``--rounds``
times, so a shared machine's load falls on each alike.

    python bench/tracker_step.py --tree before=/tmp/before --tree after=. --out bench/results/tracker_step.txt
"""

from __future__ import annotations

import argparse
import copy
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SESSION = "/tmp/skyfix-bench/uuvs3_1080p_20s"  # bench/offline_speed.py --uuvs 1080p makes it


def replay(session: str, uuv: str, repeats: int) -> dict:
    """Record one ``skyfix process`` run's tracking steps and replay them: CPU ms per step and the digest."""
    from groundstation import cli
    from localizer.tracking.session import TrackingSession

    states, steps, images, chromas, poses = {}, [], {}, {}, {}
    step = TrackingSession.step

    def recording(self, frame, pose, i=0, prior=None, chroma=None):
        if id(self) not in states:
            states[id(self)], poses[id(self)] = copy.deepcopy(self), pose
        if i not in images:  # copies: the decoder reuses its frames' buffers
            images[i], chromas[i] = frame.copy(), None if chroma is None else chroma.copy()
        steps.append((id(self), i))
        return step(self, frame, pose, i, prior, chroma)

    TrackingSession.step = recording
    with tempfile.TemporaryDirectory() as out:
        args = ["process", session, "--uuv", uuv, "--out", out, "--quiet"]
        cli.main([*args, "--height-from-size", "off"])
    TrackingSession.step = step
    best, digests = float("inf"), set()
    for _ in range(repeats):
        sessions = {k: copy.deepcopy(s) for k, s in states.items()}
        digest, cpu_s = hashlib.sha256(), 0.0
        for k, i in steps:
            t0 = time.thread_time()
            result = sessions[k].step(images[i], poses[k], i, chroma=chromas[i])
            cpu_s += time.thread_time() - t0
            digest.update(repr(result).encode())
        digests.add(digest.hexdigest()[:16])
        best = min(best, cpu_s)
    return {"steps": len(steps), "ms_per_step": 1e3 * best / len(steps), "digest": sorted(digests)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--session", default=SESSION)
    ap.add_argument("--uuv", default="all")
    ap.add_argument("--tree", action="append", default=[], metavar="LABEL=DIR")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--out")
    ap.add_argument("--replay", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.replay:
        print(json.dumps(replay(a.session, a.uuv, a.repeats)))
        return
    trees = [t.split("=", 1) for t in a.tree] or [["here", str(Path(__file__).parents[1])]]
    lines = [f"{a.session} --uuv {a.uuv}; load average {os.getloadavg()[0]:.1f}"]
    for r in range(a.rounds):
        for label, tree in trees:
            argv = [sys.executable, str(Path(__file__).resolve()), "--replay"]
            argv += ["--session", a.session, "--uuv", a.uuv, "--repeats", str(a.repeats)]
            env = {**os.environ, "PYTHONPATH": str(Path(tree).resolve())}
            run = subprocess.run(
                argv, cwd=tree, env=env, capture_output=True, text=True, check=True
            )
            got = json.loads(run.stdout.strip().splitlines()[-1])
            lines.append(
                f"round {r + 1} {label}: {got['ms_per_step']:.3f} ms CPU per UUV-frame "
                f"({got['steps']} steps, best of {a.repeats}), digest {' '.join(got['digest'])}"
            )
            print(lines[-1], flush=True)
    lines.append(f"load average {os.getloadavg()[0]:.1f}")
    if a.out:
        Path(a.out).write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
