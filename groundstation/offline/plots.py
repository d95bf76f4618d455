"""The report's PNG plots, made to be read in the field without help.

:func:`write_plots` draws, for one session and one or more runs of it (``evaluate``'s
refraction and straight ray, or ``report``'s positions.csv):

- ``top_view.png``: the fixes seen from above in metres east and north of a stated
  origin (its latitude and longitude in the title), a north arrow, the truth as a
  line when there is one, where the track was lost, colour = the fix's 1-sigma
  accuracy (one run) or the method (several); over the bottom's mosaic (``skyfix mosaic``'s GeoTIFF) when
  there is one;
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
from localizer.geodesy import geodetic_to_ned, ned_to_geodetic
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
MAP_MARGIN_M = 3.0  # the top view shows at least this much of the mosaic around the track
MAP_MAX_PX = 1500  # the mosaic under the top view is resampled to at most this many pixels a side
DPI = 100
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


def mosaic_ne(mosaic: Path, lat0: float, lon0: float, limits_ne_m) -> tuple[np.ndarray, tuple]:
    """The mosaic GeoTIFF resampled onto the top view's plane (metres east and north of ``lat0``, ``lon0``, as
    :func:`localizer.geodesy.geodetic_to_ned`) over ``limits_ne_m`` (east min, east max, north min, north max):
    each output pixel's centre to latitude/longitude (:func:`localizer.geodesy.ned_to_geodetic`), to the mosaic's
    CRS (GDAL) and sampled there (bilinear); returns the RGBA image (rows north to south, transparent where the
    mosaic is not) and its extent (east min, east max, north min, north max), m, for ``imshow``. Only the part of
    the mosaic under the view is read, decimated to the view's resolution."""
    import cv2
    import rasterio
    from rasterio.crs import CRS
    from rasterio.warp import transform
    from rasterio.windows import Window

    e0, e1, n0, n1 = limits_ne_m
    with rasterio.open(mosaic) as d:
        gsd = abs(d.transform.a)
        step = max(gsd, max(e1 - e0, n1 - n0) / MAP_MAX_PX)
        w, h = int(np.ceil((e1 - e0) / step)), int(np.ceil((n1 - n0) / step))
        east = e0 + (np.arange(w) + 0.5) * step
        north = n1 - (np.arange(h) + 0.5) * step
        nn, ee = np.meshgrid(north, east, indexing="ij")
        lat, lon, _ = ned_to_geodetic(nn, ee, 0.0, lat0, lon0, 0.0)
        x, y = transform(CRS.from_epsg(4326), d.crs, lon.ravel(), lat.ravel())
        inv, x, y = ~d.transform, np.asarray(x), np.asarray(y)
        col, row = inv.a * x + inv.b * y + inv.c, inv.d * x + inv.e * y + inv.f
        col, row = col.reshape(h, w) - 0.5, row.reshape(h, w) - 0.5  # pixel centres at integers
        c0, r0 = max(0, int(np.floor(col.min()))), max(0, int(np.floor(row.min())))
        c1, r1 = (
            min(d.width, int(np.ceil(col.max())) + 2),
            min(d.height, int(np.ceil(row.max())) + 2),
        )
        image = np.zeros((h, w, 4), np.uint8)
        if c1 <= c0 or r1 <= r0:
            return image, (e0, e0 + w * step, n1 - h * step, n1)
        f = max(1, int(step / gsd))  # read decimated where the view is coarser than the mosaic
        shape = (4, max(1, (r1 - r0) // f), max(1, (c1 - c0) // f))
        data = d.read((1, 2, 3, 4), window=Window(c0, r0, c1 - c0, r1 - r0), out_shape=shape)
    sx, sy = shape[2] / (c1 - c0), shape[1] / (r1 - r0)
    map_x = ((col - c0 + 0.5) * sx - 0.5).astype(np.float32)
    map_y = ((row - r0 + 0.5) * sy - 0.5).astype(np.float32)
    image = cv2.remap(
        np.ascontiguousarray(np.moveaxis(data, 0, -1)),
        map_x,
        map_y,
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=0,
    )
    return image, (e0, e0 + w * step, n1 - h * step, n1)


def _view_limits(points_ne: list[np.ndarray]) -> tuple[float, float, float, float]:
    """East min/max, north min/max (m) around the points ((N, 2): north, east), :data:`MAP_MARGIN_M` or a fifth of
    the span beyond, whichever is more."""
    pts = np.concatenate([p for p in points_ne if len(p)])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = np.maximum(MAP_MARGIN_M, 0.2 * (hi - lo))
    (n0, e0), (n1, e1) = lo - pad, hi + pad
    return float(e0), float(e1), float(n0), float(n1)


def top_view(
    path: Path,
    name: str,
    fixes_by_run: dict[str, Fixes],
    truth: dict | None,
    mosaic: Path | None = None,
) -> dict | None:
    """``top_view.png`` (see the module doc), over the ``mosaic`` GeoTIFF (:func:`mosaic_ne`) when given. Returns
    where the plane is in the PNG: ``origin_deg`` (lat, lon), the axes' ``east_m`` and ``north_m`` limits and
    ``axes_px`` (left, top, right, bottom pixel edges, rows from the top), or None without a fix to draw."""
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

    fig, ax = plt.subplots(figsize=(7.5, 7), dpi=DPI)
    drawn: list[np.ndarray] = []
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
            drawn.append(np.column_stack([n, e]))
        single = len(fixes_by_run) == 1
        for k, (method, fixes) in enumerate(fixes_by_run.items()):
            good = fixes.status == "ok"
            n, e = ne(fixes.lat[good], fixes.lon[good])
            drawn.append(np.column_stack([n, e]))
            if single:
                sc = ax.scatter(
                    e, n, c=fixes.h_acc_m[good], s=9, cmap="viridis", zorder=3, label="fix"
                )
                fig.colorbar(
                    sc,
                    ax=ax,
                    shrink=0.8,
                    label="h_acc: claimed horizontal accuracy (m; 2·h_acc holds 95 %)",
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
        drawn.append(np.zeros((1, 2)))
        if mosaic is not None:  # the view's limits the mosaic's, the axes' box shaped to them
            _under(ax, mosaic, lat0, lon0, _view_limits(drawn))
        ax.set_aspect("equal", adjustable="box" if mosaic is not None else "datalim")
        ax.set_xlabel("east of the origin (m)")
        ax.set_ylabel("north of the origin (m)")
        over = (
            f"\nover the mosaic {mosaic.name} ({mosaic.parent.name}/)" if mosaic is not None else ""
        )
        ax.set_title(
            f"{name}: top view\norigin (0, 0) = {_origin_text(lat0, lon0)} ({where}), WGS84{over}",
            fontsize=11,
        )
        ax.grid(True, alpha=0.3)
        ax.legend(loc="lower left", fontsize=8, framealpha=0.9)
        _north_arrow(ax)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    where_px = None
    if lat0 is not None:
        left, bottom, right, top = ax.get_window_extent().extents
        height = fig.get_size_inches()[1] * DPI
        where_px = {
            "origin_deg": (lat0, lon0),
            "east_m": ax.get_xlim(),
            "north_m": ax.get_ylim(),
            "axes_px": (left, height - top, right, height - bottom),
        }
    plt.close(fig)
    return where_px


def _under(ax, mosaic: Path, lat0: float, lon0: float, limits) -> None:
    """The mosaic under everything drawn, the axes' limits set to ``limits`` (east min/max, north min/max, m)."""
    e0, e1, n0, n1 = limits
    image, extent = mosaic_ne(mosaic, lat0, lon0, limits)
    ax.set_autoscale_on(False)
    ax.imshow(image, extent=extent, origin="upper", zorder=0, interpolation="bilinear")
    ax.set_xlim(e0, e1)
    ax.set_ylim(n0, n1)


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
            t,
            fixes.h_acc_m,
            "-",
            lw=1.2,
            color=c,
            alpha=0.7,
            label=f"{label}h_acc (2·h_acc holds 95 %)",
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
    mosaic: Path | None = None,
) -> list[Path]:
    """The three PNGs into ``out_dir``; the first run gives the statuses; the top view over ``mosaic``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [out_dir / "top_view.png", out_dir / "timeline.png", out_dir / "status.png"]
    top_view(paths[0], name, fixes_by_run, truth, mosaic)
    timeline(paths[1], name, fixes_by_run, errors_by_run)
    status_breakdown(paths[2], name, next(iter(fixes_by_run.values())))
    return paths
