"""Benchmark: two UUVs that pass over or beside each other never swap into a valid fix (issue 29).

    .venv/bin/python bench/two_uuvs.py [--out bench/results/two_uuvs.txt]

Sessions generated from ``sim_fixtures/scenarios/two_uuvs_crossing.toml`` (video included), head on at 0.2 and
0.5 m/s: uuv1 (1.0 m) passing right over uuv2 (1.6 m), and both at 1.0 m passing 0.6 m apart. Each UUV is tracked
from its own first box, located at its own depth and gated as the live service does
(:func:`groundstation.offline.fleet.gate_fleet`), with the gates joined (localizer/exchange.py) and, for comparison,
each gate alone. Per UUV: valid fixes; valid fixes nearer the other vehicle (their pixel nearer the other UUV's
track.csv pixel than its own, as tests/test_sim_two_uuvs.py counts swaps; must be 0); the largest error of a valid fix
against its own truth, in metres and over its h_acc; availability after the crossing (valid fixes over frames once
the two truths are NEAR_M apart again); fixes refused as ``exchanged``.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
import pymap3d
from emit import emit

from groundstation.offline.fleet import gate_fleet
from groundstation.session.read import load_session
from localizer.exchange import NEAR_M
from sim_fixtures.generate import generate
from sim_fixtures.scenario import load_scenario, with_overrides

SCENARIO = (
    Path(__file__).resolve().parents[1] / "sim_fixtures" / "scenarios" / "two_uuvs_crossing.toml"
)


def cases():
    """(name, scenario overrides): passing right over at different depths, beside at one depth, 0.2 and 0.5 m/s."""
    for speed, pass_s in ((0.2, 4.0), (0.5, 3.0)):
        common = {
            "duration_s": 2.5 * pass_s,
            "uuv": {"east_m": -speed * pass_s, "speed_mps": speed, "weave_m": 0.0},
        }
        yield (
            f"over_{speed:g}mps_1.0m_1.6m",
            common | {"second_uuv": {"pass_at_s": pass_s, "speed_mps": speed, "miss_m": 0.0}},
        )
        yield (
            f"beside_{speed:g}mps_both_1.0m",
            common
            | {
                "second_uuv": {
                    "pass_at_s": pass_s,
                    "speed_mps": speed,
                    "miss_m": 0.6,
                    "depth_m": 1.0,
                }
            },
        )


def local_ne(sc, lat, lon) -> np.ndarray:
    s = sc.site
    n, e, _ = pymap3d.geodetic2ned(
        lat, lon, s.surface_amsl_m, s.lat_deg, s.lon_deg, s.surface_amsl_m
    )
    return np.column_stack([n, e])


def measure(sc, path: Path, joined: bool) -> dict:
    gated = gate_fleet(path, joined=joined)
    ids = list(gated)
    sessions = {i: load_session(path, uuv=i) for i in ids}
    out = {}
    for own in ids:
        other = next(i for i in ids if i != own)
        g, f = gated[own], gated[own].fixes
        px = np.column_stack([f.u, f.v])
        to_px = {
            i: np.hypot(*(px - np.column_stack([sessions[i].track["u"], sessions[i].track["v"]])).T)
            for i in ids
        }
        truth = {
            i: local_ne(
                sc,
                np.interp(f.t_unix, s.truth["t"], s.truth["lat"]),
                np.interp(f.t_unix, s.truth["t"], s.truth["lon"]),
            )
            for i, s in sessions.items()
        }
        err_m = np.hypot(*(local_ne(sc, f.lat, f.lon) - truth[own]).T)
        apart_m = np.hypot(*(truth[own] - truth[other]).T)
        closest = int(np.argmin(apart_m))
        after = (np.arange(len(f)) > closest) & (apart_m >= NEAR_M)
        v = g.valid
        out[own] = {
            "frames": len(f),
            "valid": int(v.sum()),
            "valid_nearer_other": int((v & (to_px[other] < to_px[own])).sum()),
            "max_err_m": round(float(err_m[v].max()), 3) if v.any() else None,
            "max_err_over_h_acc": round(float((err_m / f.h_acc_m)[v].max()), 2)
            if v.any()
            else None,
            "availability_after": round(float(v[after].mean()), 3) if after.any() else None,
            "exchanged": int(sum(w == "exchanged" for w in g.words)),
        }
    return out


def line(name: str, joined: bool, r: dict) -> str:
    return f"  {name:28s} {'joined' if joined else 'alone ':6s} " + "; ".join(
        f"{i}: valid {x['valid']}/{x['frames']}, nearer the other {x['valid_nearer_other']}, max err "
        f"{x['max_err_m']} m = {x['max_err_over_h_acc']} h_acc, after {x['availability_after']}, "
        f"exchanged {x['exchanged']}"
        for i, x in r.items()
    )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path)
    args = p.parse_args()
    lines, data = ["two UUVs crossing, each tracked from its own box, gates joined vs alone:"], {}
    base = load_scenario(SCENARIO)
    with tempfile.TemporaryDirectory() as d:
        for name, overrides in cases():
            sc = with_overrides(base, **overrides)
            path = generate(sc, Path(d) / name).session
            data[name] = {}
            for joined in (True, False):
                r = measure(sc, path, joined)
                data[name]["joined" if joined else "alone"] = r
                lines.append(line(name, joined, r))
                print(lines[-1], flush=True)
    emit(lines, args.out, data)


if __name__ == "__main__":
    main()
