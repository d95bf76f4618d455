"""Where the height from the UUV's size spends its CPU in ``skyfix process`` (issue 30): per outcome, the outline scan
before the fit and the fit's passes, and what stopping the failing measurements early could save at most.

    .venv/bin/python bench/size_cost.py [--session DIR] [--uuv all] [--repeats 3]
                                        [--out bench/results/size_cost.txt] [--base DIR]

Runs ``skyfix process`` on the session (default: ``bench/offline_speed.py``'s three-UUV 1080p one,
``/tmp/skyfix-bench/uuvs3_1080p_20s``; a bundled session of ``sim_fixtures/bundled`` works too) in this process,
``--repeats`` times, and times each measurement (:func:`localizer.tracking.silhouette.measure`) and each of its
fit's passes (``_pass``) with the measuring thread's CPU time (``time.thread_time``). A measurement's outcome is
known only once its passes are done (``no_convergence`` after the last of ``SilhouetteParams.passes``,
``poor_fit`` from the last pass's residual and support), after the scan of outline sizes (step 2 of the module
doc). Per outcome it prints the count, the CPU of the scan and of the passes (the medians over the repeats), the
passes taken, and two bounds on stopping early:

- capping the passes at fewer: the CPU of the passes beyond the cap, and the measurements whose outcome the cap
  changes (those that needed more passes: an ``ok`` beyond it would be lost);
- stopping every failing measurement right after its scan (an oracle that knows the outcome): the CPU of all the
  failing measurements' passes.

The machine's 1-minute load average after each repeat is printed (CPU times move little with it).

``--base DIR`` measures the source tree at DIR (an export of another commit) and this one interleaved (base, this,
base, ...: each repeat a process of its own, with the tree first on its ``PYTHONPATH``), prints both, the median CPU of all measurements and per measurement, and whether the two give the same
measurements (the same outcomes, heights, headings and pixels, in the same order).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

from emit import emit

SESSION = Path("/tmp/skyfix-bench/uuvs3_1080p_20s")
CAPS = (4, 5, 6, 7)


def measured(session: Path, uuv: str) -> list[dict]:
    """Runs ``skyfix process`` and returns each measurement's outcome, CPU seconds and its passes' CPU seconds."""
    from groundstation import height_from_size
    from groundstation.cli import main
    from localizer.tracking import silhouette

    log: list[dict] = []
    measure, one_pass = silhouette.measure, silhouette._pass

    def timed_pass(*args):
        t0 = time.thread_time()
        try:
            return one_pass(*args)
        finally:
            log[-1]["passes"].append(time.thread_time() - t0)

    def timed_measure(*args, **kwargs):
        log.append({"passes": []})
        t0 = time.thread_time()
        result = measure(*args, **kwargs)
        log[-1]["cpu_s"] = time.thread_time() - t0
        log[-1]["outcome"] = result if isinstance(result, str) else "ok"
        if not isinstance(result, str):  # what a change must keep: repr, every digit
            log[-1]["result"] = repr(
                (result.camera_height_m, result.sigma_m, result.heading_rad, result.u, result.v)
            )
        return result

    silhouette._pass, height_from_size.measure = timed_pass, timed_measure
    try:
        with (
            tempfile.TemporaryDirectory() as out,
            contextlib.redirect_stdout(io.StringIO()),
            contextlib.redirect_stderr(io.StringIO()),
        ):
            main(["process", str(session), "--out", out, "--quiet", "--uuv", uuv])
    finally:
        silhouette._pass, height_from_size.measure = one_pass, measure
    return log


def summary(log: list[dict]) -> dict:
    """CPU seconds per outcome (scan, passes), the passes taken, and what capping or an oracle would save (the outcomes a cap changes: an ok or another word
    beyond it ends as ``no_convergence``)."""
    out: dict = {"outcomes": {}, "caps": {}}
    for m in log:
        o = out["outcomes"].setdefault(
            m["outcome"], {"count": 0, "scan_s": 0.0, "passes_s": 0.0, "passes": Counter()}
        )
        o["count"] += 1
        o["passes_s"] += sum(m["passes"])
        o["scan_s"] += m["cpu_s"] - sum(m["passes"])
        o["passes"][len(m["passes"])] += 1
    out["total_s"] = sum(m["cpu_s"] for m in log)
    out["failing_s"] = sum(m["cpu_s"] for m in log if m["outcome"] != "ok")
    out["failing_passes_s"] = sum(sum(m["passes"]) for m in log if m["outcome"] != "ok")
    for cap in CAPS:
        out["caps"][cap] = {
            "saved_s": sum(sum(m["passes"][cap:]) for m in log),
            "ok_lost": sum(1 for m in log if m["outcome"] == "ok" and len(m["passes"]) > cap),
            # beyond the cap a measurement ends as no_convergence
            "changed": sum(
                1 for m in log if len(m["passes"]) > cap and m["outcome"] != "no_convergence"
            ),
        }
    return out


def report(args, runs: list[dict], loads: list[float]) -> list[str]:
    """The printed summary of ``runs`` (of :func:`summary`)."""

    def med(f):
        return statistics.median(f(r) for r in runs)

    first = runs[0]
    count = sum(o["count"] for o in first["outcomes"].values())
    total = med(lambda r: r["total_s"])
    failing, failing_passes = med(lambda r: r["failing_s"]), med(lambda r: r["failing_passes_s"])
    lines = [
        f"# bench/size_cost.py --session {args.session} --uuv {args.uuv} --repeats {args.repeats}",
        f"# {count} measurements; thread CPU, median over the repeats; load average (1 min) after each repeat: "
        + ", ".join(f"{x:.1f}" for x in loads),
        f"all measurements {total:.3f} s ({total / count * 1e3:.1f} ms each); failing {failing:.3f} s "
        + f"({failing / total:.0%}); their passes {failing_passes:.3f} s ({failing_passes / total:.0%}: what an "
        + "oracle stopping each failing measurement right after its scan would save)",
        "scan: before the first pass (the candidate headings, the scan of outline sizes); passes: the fit's",
        f"{'outcome':16s}{'count':>6s}{'scan s':>9s}{'passes s':>10s}  passes taken (number: measurements)",
    ]
    for name, o in sorted(first["outcomes"].items(), key=lambda kv: -kv[1]["count"]):
        scan = med(lambda r, n=name: r["outcomes"].get(n, {}).get("scan_s", 0.0))
        passes = med(lambda r, n=name: r["outcomes"].get(n, {}).get("passes_s", 0.0))
        taken = ", ".join(f"{k}: {v}" for k, v in sorted(o["passes"].items()))
        lines.append(f"{name:16s}{o['count']:6d}{scan:9.3f}{passes:10.3f}  {taken}")
    for cap, c in first["caps"].items():
        saved = med(lambda r, k=cap: r["caps"][k]["saved_s"])
        lines.append(
            f"passes capped at {cap}: saves {saved:.3f} s ({saved / total:.1%}); outcomes changed {c['changed']} "
            f"of {count} "
            f"(ok lost: {c['ok_lost']})"
        )
    return lines


def one_run(tree: Path, args) -> tuple[dict, list[dict]]:
    """One repeat in a process of its own on the source tree ``tree``: its summary and its measurements."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run.txt"
        subprocess.run(
            [sys.executable, __file__, "--session", str(args.session), "--uuv", args.uuv]
            + ["--repeats", "1", "--out", str(out)],
            check=True,
            stdout=subprocess.DEVNULL,
            env=dict(os.environ, PYTHONPATH=str(tree)),
        )
        data = json.loads(out.with_suffix(".json").read_text())
    return data["runs"][0], data["log"]


def compare(args) -> None:
    """``--base``: the base tree and this one interleaved, and whether their measurements are the same."""
    this = Path(__file__).resolve().parents[1]
    trees = {"base": args.base.resolve(), "this": this}
    runs: dict = {name: [] for name in trees}
    loads: dict = {name: [] for name in trees}
    logs: dict = {}
    for _ in range(args.repeats):
        for name, tree in trees.items():
            summary_, log = one_run(tree, args)
            runs[name].append(summary_)
            loads[name].append(os.getloadavg()[0])
            logs.setdefault(name, log)
    keep = [(m["outcome"], m.get("result")) for m in logs["base"]]
    got = [(m["outcome"], m.get("result")) for m in logs["this"]]
    changed = sum(a != b for a, b in zip(keep, got)) + abs(len(keep) - len(got))
    lines = [
        f"# bench/size_cost.py --base {trees['base']} (base) against {this} (this), interleaved, "
        + f"{args.repeats} repeats each, a process each",
    ]
    for name in trees:
        total = statistics.median(r["total_s"] for r in runs[name])
        count = sum(o["count"] for o in runs[name][0]["outcomes"].values())
        lines.append(
            f"{name}: all measurements {total:.3f} s, {total / count * 1e3:.2f} ms each (thread CPU, median; "
            + "each repeat: "
            + ", ".join(f"{r['total_s']:.3f}" for r in runs[name])
            + "; load after each: "
            + ", ".join(f"{x:.1f}" for x in loads[name])
            + ")"
        )
    lines.append(
        f"measurements the same: {len(keep) - changed} of {len(keep)} (outcomes, heights, headings, pixels)"
        + (" (identical)" if changed == 0 else f"; {changed} changed")
    )
    for name in trees:
        lines += [f"## {name}"] + report(args, runs[name], loads[name])
    emit(lines, args.out, {"runs": runs, "loads": loads, "changed": changed})


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--session", type=Path, default=SESSION)
    p.add_argument("--uuv", default="all")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--out", type=Path)
    p.add_argument("--base", type=Path, help="a source tree to measure interleaved with this one")
    args = p.parse_args()
    if args.base:
        compare(args)
        return
    runs, loads, logs = [], [], []
    for _ in range(args.repeats):
        logs.append(measured(args.session, args.uuv))
        runs.append(summary(logs[-1]))
        loads.append(os.getloadavg()[0])
    emit(report(args, runs, loads), args.out, {"runs": runs, "loads": loads, "log": logs[0]})


if __name__ == "__main__":
    main()
