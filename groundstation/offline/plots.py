"""The report's PNG plots, made to be read in the field without help.

:func:`write_plots` draws, for one session and one or more runs of it (``evaluate``'s
refraction and straight ray, or ``report``'s positions.csv):

- ``top_view.png``: the fixes seen from above in metres east and north of a stated
  origin (its latitude and longitude in the title), a north arrow, the truth as a
  line when there is one, where the track was lost, colour = the fix's 1-sigma
  accuracy (one run) or the method (several);
- ``timeline.png``: the horizontal error against truth and the claimed accuracy
  (h_acc and 2·h_acc) over time, or h_acc alone without truth, and a status strip;
  stretches without a fix shaded in both, by cause, and times without any frame
  (the video stopped) hatched;
- ``status.png``: frames per status word, with their share, the time they cover and
  the longest stretch.
"""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from localizer.fix import Fixes
from localizer.geodesy import geodetic_to_ned
from localizer.status import STATUSES, runs

#: cause → (colour, the status words)
CAUSES = {
    "tracking": (
        "#d62728",
        (
            "lost",
            "no_track",
            "not_initialized",
            "awaiting_target",
            "released",
            "before_init",
            "same_vehicle",
        ),
    ),
    "video": ("#9467bd", ("no_video", "buffered", "latency_unsettled")),
    "telemetry": (
        "#7f7f7f",
        (
            "no_attitude",
            "stale_attitude",
            "no_position",
            "stale_position",
            "no_gimbal",
            "stale_gimbal",
            "no_depth",
            "stale_depth",
            "bad_time",
        ),
    ),
    "geometry": ("#ff7f0e", ("bad_pixel", "no_water", "below_surface")),
    "fusion": ("#17becf", ("disagree", "off_track")),
    "gates": ("#e377c2", ("refused",)),
}
OK_COLOUR = "#2ca02c"
METHOD_COLOURS = ("tab:blue", "tab:orange", "tab:purple", "tab:brown")


def cause(word: str) -> str:
    return next((c for c, (_, words) in CAUSES.items() if word in words), "other")


def colour(word: str) -> str:
    return OK_COLOUR if word == "ok" else CAUSES.get(cause(word), ("#bcbd22",))[0]


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _origin_text(lat: float, lon: float) -> str:
    return f"{abs(lat):.6f}° {'N' if lat >= 0 else 'S'}, {abs(lon):.6f}° {'E' if lon >= 0 else 'W'}"


def _north_arrow(ax) -> None:
    ax.annotate(
        "N",
        xy=(0.94, 0.95),
        xytext=(0.94, 0.80),
        xycoords="axes fraction",
        ha="center",
        va="center",
        fontsize=14,
        fontweight="bold",
        arrowprops={"arrowstyle": "-|>", "lw": 2, "color": "black"},
    )


def _span_s(fixes: Fixes, a: int, b: int) -> float:
    """Seconds covered by frames a..b-1 (one frame period at least)."""
    period = float(np.median(np.diff(fixes.t_unix))) if len(fixes) > 1 else 0.0
    return float(fixes.t_unix[b - 1] - fixes.t_unix[a]) + period


def top_view(path: Path, name: str, fixes_by_run: dict[str, Fixes], truth: dict | None) -> None:
    plt = _pyplot()
    first = next(iter(fixes_by_run.values()))
    ok = first.status == "ok"
    if truth is not None:
        lat0, lon0 = float(truth["lat"][0]), float(truth["lon"][0])
        where = "the truth's first point"
    elif ok.any():
        i = int(np.flatnonzero(ok)[0])
        lat0, lon0, where = float(first.lat[i]), float(first.lon[i]), "the first fix"
    else:
        lat0 = lon0 = None

    def ne(lat, lon):
        n, e, _ = geodetic_to_ned(np.asarray(lat), np.asarray(lon), 0.0, lat0, lon0, 0.0)
        return n, e

    fig, ax = plt.subplots(figsize=(7.5, 7))
    if lat0 is None:
        ax.text(
            0.5,
            0.5,
            "no fix in this run",
            ha="center",
            va="center",
            fontsize=16,
            transform=ax.transAxes,
        )
        ax.set_title(f"{name}: top view")
    else:
        if truth is not None:
            n, e = ne(truth["lat"], truth["lon"])
            ax.plot(e, n, "-", color="black", lw=1.5, label="truth")
        single = len(fixes_by_run) == 1
        for k, (method, fixes) in enumerate(fixes_by_run.items()):
            good = fixes.status == "ok"
            n, e = ne(fixes.lat[good], fixes.lon[good])
            if single:
                sc = ax.scatter(
                    e, n, c=fixes.h_acc_m[good], s=9, cmap="viridis", zorder=3, label="fix"
                )
                fig.colorbar(
                    sc, ax=ax, shrink=0.8, label="h_acc: claimed 1-sigma horizontal accuracy (m)"
                )
            else:
                ax.plot(
                    e,
                    n,
                    ".",
                    ms=3,
                    color=METHOD_COLOURS[k % len(METHOD_COLOURS)],
                    label=method,
                    zorder=3,
                )
        lost_at = [a - 1 for a, b, w in runs(first.status) if w != "ok" and a > 0]
        if lost_at:
            n, e = ne(first.lat[lost_at], first.lon[lost_at])
            ax.plot(
                e,
                n,
                "x",
                color=CAUSES["tracking"][0],
                ms=10,
                mew=2,
                zorder=4,
                label="last fix before a gap",
            )
        idx = np.flatnonzero(ok)
        if len(idx):
            n, e = ne(first.lat[idx[[0, -1]]], first.lon[idx[[0, -1]]])
            ax.plot(e[0], n[0], "^", color="black", ms=9, zorder=5, label="first fix")
            ax.plot(e[1], n[1], "s", color="black", ms=8, mfc="none", zorder=5, label="last fix")
        ax.plot(0, 0, "+", color="black", ms=14, mew=1.5, zorder=2)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("east of the origin (m)")
        ax.set_ylabel("north of the origin (m)")
        ax.set_title(
            f"{name}: top view\norigin (0, 0) = {_origin_text(lat0, lon0)} ({where}), WGS84",
            fontsize=11,
        )
        ax.grid(True, alpha=0.3)
        ax.legend(loc="lower left", fontsize=8, framealpha=0.9)
        _north_arrow(ax)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def frame_gaps(t_unix: np.ndarray) -> list[tuple[float, float]]:
    """Intervals with no frame at all (the video stopped): more than 3 frame periods between frames."""
    if len(t_unix) < 3:
        return []
    dt = np.diff(t_unix)
    period = float(np.median(dt))
    return [(float(t_unix[i]), float(t_unix[i + 1])) for i in np.flatnonzero(dt > 3 * period)]


def _shade(axes, fixes: Fixes, t0: float, alpha: float) -> set[str]:
    """Shade the stretches without a fix by cause, and those without frames; returns what was shaded."""
    shaded = set()
    half = 0.5 * (float(np.median(np.diff(fixes.t_unix))) if len(fixes) > 1 else 0.0)
    for ax in axes:
        for a, b, w in runs(fixes.status):
            if w != "ok" or alpha == 1.0:
                ax.axvspan(
                    fixes.t_unix[a] - t0 - half,
                    fixes.t_unix[b - 1] - t0 + half,
                    color=colour(w),
                    alpha=alpha,
                    lw=0,
                )
                shaded.add(cause(w) if w != "ok" else "ok")
        for a, b in frame_gaps(fixes.t_unix):
            ax.axvspan(
                a - t0 + half,
                b - t0 - half,
                facecolor="none",
                edgecolor="#555555",
                hatch="//",
                lw=0,
            )
            shaded.add("no frames")
    return shaded


def timeline(
    path: Path,
    name: str,
    fixes_by_run: dict[str, Fixes],
    errors_by_run: dict[str, np.ndarray] | None,
):
    plt = _pyplot()
    from matplotlib.patches import Patch

    first = next(iter(fixes_by_run.values()))
    t0 = float(first.t_unix[0])
    fig, (ax, strip) = plt.subplots(
        2, 1, figsize=(10, 5.5), sharex=True, gridspec_kw={"height_ratios": [4, 1]}
    )
    for k, (method, fixes) in enumerate(fixes_by_run.items()):
        c = METHOD_COLOURS[k % len(METHOD_COLOURS)]
        t = fixes.t_unix - t0
        label = "" if len(fixes_by_run) == 1 else f"{method}: "
        if errors_by_run is not None:
            ax.plot(
                t, errors_by_run[method], ".", ms=3, color=c, label=f"{label}error against truth"
            )
            ax.plot(
                t,
                2 * fixes.h_acc_m,
                "--",
                lw=0.9,
                color=c,
                label=f"{label}2·h_acc (95% if the claim holds)",
            )
        ax.plot(
            t, fixes.h_acc_m, "-", lw=1.2, color=c, alpha=0.7, label=f"{label}h_acc (claimed 1σ)"
        )
    shaded = _shade([ax], first, t0, alpha=0.18)
    ax.set_ylabel("horizontal (m)")
    ax.set_ylim(bottom=0)
    ax.grid(True, alpha=0.3)
    ax.set_title(
        f"{name}: {'error and ' if errors_by_run is not None else ''}claimed accuracy over time",
        fontsize=11,
    )
    handles, _ = ax.get_legend_handles_labels()
    handles += [
        Patch(color=CAUSES[c][0], alpha=0.3, label=f"no fix: {c}") for c in CAUSES if c in shaded
    ]
    if "no frames" in shaded:
        handles.append(
            Patch(
                facecolor="none", edgecolor="#555555", hatch="//", label="no frames (video stopped)"
            )
        )
    ax.legend(handles=handles, fontsize=8, loc="upper right", framealpha=0.9)

    _shade([strip], first, t0, alpha=1.0)
    for a, b, w in runs(first.status):
        if b - a >= 0.06 * len(first):
            strip.text(
                0.5 * (first.t_unix[a] + first.t_unix[b - 1]) - t0,
                0.5,
                w,
                ha="center",
                va="center",
                fontsize=8,
                color="white" if w == "ok" else "black",
            )
    strip.set_yticks([])
    strip.set_ylabel("status", rotation=0, ha="right", va="center")
    start = datetime.fromtimestamp(t0, UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    strip.set_xlabel(f"seconds since the first frame ({start}, station clock)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def status_breakdown(path: Path, name: str, fixes: Fixes) -> None:
    plt = _pyplot()
    words, counts = np.unique(fixes.status.astype(str), return_counts=True)
    order = np.argsort(counts)
    words, counts = words[order], counts[order]
    longest = {
        w: max(_span_s(fixes, a, b) for a, b, x in runs(fixes.status) if x == w) for w in words
    }
    seconds = {
        w: sum(_span_s(fixes, a, b) for a, b, x in runs(fixes.status) if x == w) for w in words
    }
    fig, ax = plt.subplots(figsize=(11, 1.3 + 0.55 * len(words)))
    labels = [w if w == "ok" else f"{w}\n({cause(w)})" for w in words]
    ax.barh(labels, counts, color=[colour(w) for w in words])
    for y, (w, n) in enumerate(zip(words, counts)):
        ax.text(
            n,
            y,
            f"  {n} ({n / len(fixes):.1%}), {seconds[w]:.1f} s, longest {longest[w]:.1f} s"
            f"\n  {STATUSES.get(w, 'not a skyfix status word')}",
            va="center",
            fontsize=8.5,
        )
    ax.set_xlim(0, counts.max() * 2.6)
    ax.set_xlabel("frames")
    total_s = _span_s(fixes, 0, len(fixes)) if len(fixes) else 0.0
    ax.set_title(f"{name}: frames by status ({len(fixes)} frames, {total_s:.1f} s)", fontsize=11)
    ax.grid(True, axis="x", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def write_plots(
    out_dir: Path,
    name: str,
    fixes_by_run: dict[str, Fixes],
    truth: dict | None = None,
    errors_by_run: dict[str, np.ndarray] | None = None,
) -> list[Path]:
    """The three PNGs into ``out_dir``; the first run gives the statuses."""
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [out_dir / "top_view.png", out_dir / "timeline.png", out_dir / "status.png"]
    top_view(paths[0], name, fixes_by_run, truth)
    timeline(paths[1], name, fixes_by_run, errors_by_run)
    status_breakdown(paths[2], name, next(iter(fixes_by_run.values())))
    return paths
