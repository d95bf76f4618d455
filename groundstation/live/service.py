"""The live service (``skyfix run``, its command line in :mod:`.command`). One asyncio task per link, all in one
TaskGroup.

Workers: the UAV's MAVLink (:mod:`.sources.uav_mavlink`), the UUV's depth (skyfix's JSON over
Zenoh, :mod:`.sources.depth_zenoh`, or ArduSub's own over BlueOS's Zenoh or MAVLink,
:mod:`.sources.depth_ardusub`; the UAV's and the depth's source are the parts the configuration names, looked up
in :mod:`.registry`), the UUV's own position estimate
(:mod:`.sources.uuv_position`), the UAV's video (:mod:`groundstation.video.live`),
the per-frame :mod:`.pipeline` (and the height from the UUV's size, :mod:`groundstation.height_from_size`),
each UUV's outputs, the parts its ``outputs`` names (by default the fixes on Zenoh and GPS_INPUT to the UUV,
:mod:`.outputs`), the 1 Hz Zenoh status (:mod:`groundstation.runtime.zenoh_fix`), the operator's commands
(:mod:`.control`), the web page (:mod:`.ui`, unless ``--no-ui``) and, with ``--record``,
the recorder (:mod:`.sinks.recorder`). The web page's port is taken before any worker
starts, so a port in use stops the service at once (exit 2). Blocking I/O lives in threads owned by the
workers (:mod:`groundstation.runtime.threads`: bounded hand-offs to the loop, supervised, never waited for at a stop);
all telemetry is written and read on the event loop.

The workers are declared in one registry (:mod:`groundstation.runtime.workers`): each with its stop stage, its
status section and whether the watchdog judges it as an input; the status is the
registry's. The pipeline is built with its sinks and frame listeners.

Stopping: SIGINT/SIGTERM (or ``--duration-s``) stop the workers in order — the inputs
(and the operator's commands and web page), then the pipeline, then the sinks — each stage
cancelled and awaited before the next (a stage slower than
:data:`~groundstation.runtime.workers.STAGE_S` is logged), and last the GPS_INPUT sink, whose
last message says "no fix". Nothing waits for a blocked read or open: the whole stop takes well under a second whatever the inputs are doing
(``bench/links.py`` measures it). A worker that fails cancels the others (the sink still
sends its no-fix) and the service exits with its error. The Zenoh session is closed in ``finally``.
"""

from __future__ import annotations

import asyncio
import dataclasses
import json
import logging
import signal
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from functools import partial
from pathlib import Path

import numpy as np
import zenoh
from pydantic import ValidationError

from groundstation.config_files import load_calibration
from groundstation.height_from_size import HeightFromSize, OnlineHeightFromSize
from groundstation.latency.estimate import OnlineLatency
from groundstation.live import config, registry
from groundstation.live.bottom_live import LiveBottom
from groundstation.live.control import Control
from groundstation.live.mosaic_live import LiveMosaic
from groundstation.live.pipeline import FramePoses, Pipeline
from groundstation.live.reference_live import BuoyZenoh, LiveReference
from groundstation.live.registry import DepthInput, OutputInput, UavInput
from groundstation.live.sinks.recorder import Recorder, new_recording
from groundstation.live.sources.rates import needed_rates
from groundstation.live.sources.uuv_position import UuvPosition, parse_hint
from groundstation.live.track_memory import TrackMemory, remember, track_path
from groundstation.live.ui.feed import VideoFeed
from groundstation.live.ui.server import PageUuv, WebUi, settings_of
from groundstation.live.ui.topview import TopView
from groundstation.live.watchdog import REQUIRE_S, InputMissing, Watchdog
from groundstation.offline.reference import read_file
from groundstation.runtime.gps_input import GpsInputSink
from groundstation.runtime.queries import ZenohControl
from groundstation.runtime.threads import realtime, start_opencv_workers
from groundstation.runtime.usage import Usage
from groundstation.runtime.workers import (
    INPUTS,
    LAST,
    OUTPUTS,
    PIPELINE,
    Workers,
    run_to_end,
    stopped,
)
from groundstation.runtime.zenoh_fix import ZenohFixSink, ZenohStatus
from groundstation.runtime.zenoh_session import open_session
from groundstation.video.live import VideoLive
from localizer.calibration import Calibration, ConfigError, Tracker
from localizer.depth import DepthGate
from localizer.exchange import Fleet
from localizer.fix_gate import FixGate
from localizer.height import status as height_status
from localizer.telemetry import Telemetry
from localizer.thrusters import Thrusters
from localizer.tracking.crowd import Crowd

log = logging.getLogger("skyfix.run")

TELEMETRY_KEEP_S = 60.0


def latency_summary(latencies_s) -> dict:
    """Percentiles (ms) of frame arrival → GPS_INPUT sent; None when nothing was measured."""
    a = np.asarray(latencies_s, dtype=float) * 1000.0
    if len(a) == 0:
        return {"n": 0, "p50_ms": None, "p99_ms": None, "max_ms": None}
    return {
        "n": len(a),
        "p50_ms": round(float(np.percentile(a, 50)), 3),
        "p99_ms": round(float(np.percentile(a, 99)), 3),
        "max_ms": round(float(a.max()), 3),
    }


async def serve(cfg: config.RunConfig) -> dict:
    """Run the service until stopped; returns the final status (with several UUVs: the shared sections and each
    UUV's own under ``uuvs``)."""
    loop = asyncio.get_running_loop()
    if cfg.realtime_priority:  # before any thread starts: each takes this one's policy
        granted, line = realtime(cfg.realtime_priority)
        (log.info if granted else log.warning)(line)
    start_opencv_workers()  # before any thread of a lower priority can
    cal = load_calibration(cfg.calibration)
    tel = Telemetry(cal.timing, keep_s=TELEMETRY_KEEP_S)
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    session = open_session(
        cfg.zenoh_connect,
        cfg.zenoh_listen_endpoints,
        multicast=cfg.zenoh_multicast,
        config_file=cfg.zenoh_config,
    )
    closers = []
    usage = Usage()
    try:
        size = (cal.camera.width, cal.camera.height)
        auto = cfg.video_latency_ms == "auto"
        fixed_latency_s = None if auto else cfg.video_latency_ms / 1000.0
        first_aligned: list[
            float
        ] = []  # auto: the exposure of the first frame stamped with the estimate
        workers = Workers()  # the UAV's and the video's; each UUV's own are in its chain's
        chains: list[
            UuvChain
        ] = []  # built once the shared parts are (below); the closures read them then
        several = len(cfg.uuvs) > 1
        if several and cal.init_bbox is not None:
            log.warning(
                "%s: [tracker] init_bbox is not used with several [[uuv]]: each UUV's own init_bbox is",
                cfg.calibration,
            )

        # -- the shared inputs: the UAV, the video ------------------------------------------------------------------
        uav = registry.part("uav", cfg.mavlink_backend).build(UavInput(cfg, cal, tel))
        uav.listeners.append(lambda *a: [c.pipeline.telemetry_arrived(*a) for c in chains])
        workers.add(uav, INPUTS, "uav", is_input=True)
        workers.section("height", lambda now: height_status(cal.water, cal.sigmas, tel))
        video = motion = from_size = None
        frame_listeners = []

        def on_frame(frame) -> None:
            """Every frame to the listeners (the recorder, the page's feed, the latency's estimator), then to each
            UUV's pipeline."""
            for listener in frame_listeners:
                listener(frame)
            for chain in chains:
                chain.pipeline.submit(frame)

        if cfg.video:
            video = VideoLive(
                cfg.video, fixed_latency_s, on_frame, expected_size=size, session=session
            )
            motion = OnlineLatency(
                cal,
                tel,
                fixed_latency_s,
                (lambda s: setattr(video, "latency_s", s)) if auto else None,
            )
            workers.add(
                video,
                INPUTS,
                "video",
                lambda now: video.status(now) | {"latency_from_motion": motion.status()},
                is_input=True,
            )
            workers.add(motion, INPUTS)
            if cfg.height_from_size != "off":
                from_size = workers.add(
                    OnlineHeightFromSize(HeightFromSize(cal, tel, cfg.height_from_size)),
                    INPUTS,
                    "height_from_size",
                    lambda now: from_size.status(),
                )

        def recorded_timing() -> dict:
            """What the run measured and used for time, for the recording's [timing]."""
            measured = tel.measured_latency_s
            out = {
                "mavlink_latency_measured_s": None if measured is None else round(measured, 4),
                "mavlink_latency_measured_from_t": tel.measured_latency_from_s,
            }
            if video is None:
                return out
            if not auto:
                return out | {
                    "video_latency_s": fixed_latency_s,
                    "video_latency_source": "configured",
                }
            if motion.applied_s is None:
                return out
            return out | {
                "video_latency_s": round(motion.applied_s, 4),
                "video_latency_source": "motion",
                "video_latency_sigma_s": round(motion.applied_sigma_s, 4),
                "video_latency_from_t": first_aligned[0] if first_aligned else None,
            }

        # -- the shared outputs: the recording and the page (each UUV its part of them) -----------------------------
        recorder = None
        if cfg.recording:
            folder = cfg.record or new_recording(cfg.recordings, time.time())
            log.info("recording into %s", folder)
            recorder = Recorder(
                folder,
                cfg.calibration,
                video_size=size if cfg.video else None,
                timing=recorded_timing,
                uuv_ids=tuple(u.id for u in cfg.uuvs),
            )
            uav.listeners.append(recorder.on_mavlink)
            workers.add(recorder, OUTPUTS, "record", lambda now: recorder.status(), is_input=True)

        def zenoh_peers() -> int:
            return len(list(session.info.peers_zid())) + len(list(session.info.routers_zid()))

        topview = feed = None
        if not cfg.no_ui:
            topview = TopView(cal, tel, uuvs=len(cfg.uuvs))
            targets = [
                (u.id, lambda i=i: chains[i].pipeline.target) for i, u in enumerate(cfg.uuvs)
            ]
            feed = VideoFeed(targets if several else targets[0][1])
        mosaic = None
        if cfg.live_mosaic and feed and video:  # the page's base map, grown from the video
            mosaic = LiveMosaic(cal, tel, cfg.floor_depth_m, cfg.live_mosaic_every_s)
            workers.section("live_mosaic", lambda now: mosaic.status())
            closers.append(mosaic.close)
        reference = None
        if (
            cfg.reference and video
        ):  # a surveyed marker in view: the drone's absolute offset added to every fix
            found = read_file(Path(cfg.reference))
            reference = LiveReference(cal, tel, cfg.reference, *found, cfg.reference_every_s)
            if reference.buoy:  # its GNSS reports come on the UAV's link from its own system
                uav.not_uav.add(reference.buoy.buoy.system_id)
                uav.others.append(reference.buoy.on_mavlink)
                if cfg.reference_zenoh_key:  # and on Zenoh
                    workers.add(BuoyZenoh(session, cfg.reference_zenoh_key, reference.buoy), INPUTS)
            workers.section("reference", reference.status)
            closers.append(reference.close)

        bottom = None
        if (
            cfg.pose_from_bottom and video
        ):  # the drone's pose biases from the static bottom, causally
            bottom = LiveBottom(cal, tel, cfg.bottom_every_s, cfg.bottom_window_s)
            workers.section("bottom", bottom.status)
            closers.append(bottom.close)
            if reference:  # its sightings through the bottom's corrected pose: its offset is what is left after it
                reference.sight_through(bottom.pose_only)
        correct = (
            bottom.then(reference.correct)
            if bottom and reference
            else (bottom and bottom.correct) or (reference and reference.correct)
        )

        def first_aligned_frame(frame) -> None:
            if frame.aligned and not first_aligned:
                first_aligned.append(frame.t_unix)

        frame_listeners += [
            f
            for f in (
                recorder and recorder.on_frame,
                feed and feed.on_frame,
                motion and motion.on_frame,
                motion and auto and first_aligned_frame,
                mosaic and mosaic.on_frame,
                reference and reference.on_frame,
                bottom and bottom.on_frame,
            )
            if f
        ]
        if video and auto:
            log.info(
                "--video-latency-ms auto: no valid fix until the video's latency from the image's motion "
                "has settled (status latency_unsettled)"
            )
        workers.section("zenoh", lambda now: {"peers": zenoh_peers()})
        workers.section("process", usage.status)

        # -- each UUV: its depth, its own position, its tracker and its outputs -------------------------------------
        crowd = Crowd() if several else None  # two trackers on one vehicle: no fix for either
        fleet = Fleet() if several else None  # the gates compare each target with the other UUVs'
        # one thread for all (a thread each contended for the interpreter's lock: bench/uuvs.py)
        tracking = ThreadPoolExecutor(1, thread_name_prefix="track") if several else None
        poses = FramePoses(cal, tel)  # each frame's pose computed once for all the UUVs
        if tracking:
            closers.append(lambda: tracking.shutdown(wait=False, cancel_futures=True))
        for i, u in enumerate(cfg.uuvs):
            uuv_tel = Telemetry(cal.timing, keep_s=TELEMETRY_KEEP_S) if several else tel
            page = (feed.sinks[i], topview.tracks[i]) if feed else (None, None)
            uuv_cal = uuv_calibration(cal, u, cfg.calibration) if several else cal
            chain = UuvChain(
                cfg,
                u,
                uuv_cal,
                tel,
                uuv_tel,
                session,
                workers,
                page,
                recorder.of(u.id) if recorder else None,
                zenoh_peers,
                alignment=(lambda: ("motion", motion.applied_sigma_s)) if video and auto else None,
                vet=partial(crowd.vet, u.id) if crowd else None,
                tracking=tracking,
                poses=poses,
                fleet=fleet,
                on_tracked=[
                    f
                    for f in (from_size and from_size.on_tracked, bottom and bottom.on_tracked)
                    if f
                ],
                correct=correct,
            )
            chains.append(chain)
            workers.include(chain.workers)

        # -- the operator's page: every UUV, each with its commands and its own status --------------------------------
        page_uuvs = [
            PageUuv(c.uuv.id, c.control, c.workers.status, c.gps.sending if c.gps else None)
            for c in chains
        ]
        ui = (
            WebUi(
                cfg.ui,
                cfg.ui_token,
                page_uuvs,
                topview,
                feed,
                size,
                settings_of(cfg),
                mosaic or cfg.basemap,
            )
            if feed
            else None
        )
        if ui:
            workers.add(ui, INPUTS, "ui", lambda now: ui.status())
            # UiError (an OSError) when its port is taken: exit 2 before anything runs
            await ui.start()
        for chain in chains:
            u = chain.uuv
            log.info(
                "skyfix run: UAV %s, video %s, UUV %s: depth %s (%s), fixes on %s, GPS_INPUT %s, commands on "
                "%s/*",
                cfg.mavlink,
                cfg.video,
                u.id,
                u.depth_mavlink or u.depth_input_key,
                u.depth_source,
                u.fix_key,
                u.gps_input,
                chain.zenoh_control.prefix,
            )
            if chain.pipeline.cal.init_bbox is None:
                log.info(
                    "UUV %s: no init_bbox: awaiting a target (%s/select%s%s)",
                    u.id,
                    chain.zenoh_control.prefix,
                    f", the web page {ui.url}" if ui else "",
                    ", or near the UUV's own position" if u.uuv_position_key or u.uuv_hint else "",
                )
        await workers.run(stopped(stop, cfg.duration_s))
        now = time.time()
        if not several:
            return chains[0].final(now)
        return workers.status(now) | {
            "uuvs": {c.uuv.id: c.final(now, shared=False) for c in chains}
        }
    finally:
        for close in closers:
            close()
        session.close()


def uuv_outputs(
    cfg: config.RunConfig, u: config.UuvConfig, session, gate, workers: Workers
) -> list:
    """The UUV's outputs (``outputs``, registered parts) built by name, each run with ``workers`` (stopped last,
    once the pipeline is) with its status: its own section, or under ``outputs`` by name."""
    built, listed = [], {}
    for name in u.outputs:
        part = registry.part("output", name)
        settings = registry.settings(part, u.parts.get(name, {}))
        out = part.build(OutputInput(name, u, cfg, session, gate, settings))
        if out is None:  # nothing to send for this UUV (gps_input none)
            continue
        if not isinstance(out, registry.Output):
            raise ConfigError(
                f"output {name} ({part.build.__module__})",
                "build()",
                type(out).__name__,
                "not an output: it needs run(), status(now) and on_fix(fix, info)",
            )
        built.append(workers.add(out, LAST, part.section))
        if part.section is None:
            listed[name] = out
    if listed:
        workers.section("outputs", lambda now: {n: o.status(now) for n, o in listed.items()})
    return built


def uuv_calibration(cal: Calibration, u: config.UuvConfig, source: str) -> Calibration:
    """The calibration with one UUV's own first box (``[[uuv]] init_bbox``) as ``[tracker]``."""
    try:
        return dataclasses.replace(cal, tracker=Tracker(init_bbox=u.init_bbox))
    except ValidationError:
        raise ConfigError(
            source,
            f"[[uuv]] {u.id}: init_bbox",
            list(u.init_bbox),
            f"box must lie inside the {cal.camera.width}x{cal.camera.height} image",
        ) from None


class UuvChain:
    """One UUV's part of the service: its depth (and thrusters) and own position estimate, the pipeline that
    tracks it in the shared video with the shared pose, its fixes on Zenoh, its GPS_INPUT through its own gates,
    its watchdog, its operator's commands and its 1 Hz status (the shared sections and its own). Its workers are in
    :attr:`workers`, run with the service's."""

    def __init__(
        self,
        cfg: config.RunConfig,
        u: config.UuvConfig,
        cal,
        tel: Telemetry,
        uuv_tel: Telemetry,
        session,
        shared: Workers,
        page: tuple,
        recorder,
        zenoh_peers: Callable[[], int],
        alignment,
        on_tracked,
        vet=None,
        tracking=None,
        fleet=None,
        poses=None,
        correct=None,
    ):
        self.uuv = u
        self.workers = own = Workers()
        self._shared = shared
        depth_gate = DepthGate(cfg.uuv_max_vertical_speed_mps, cal.sigmas.depth_m)
        # the UUV's thrusters, read with its depth from ArduSub: the fix gate's second source of the UUV's motion
        source = registry.part("depth", u.depth_source)
        thrusters = Thrusters(cfg.thruster_deadband_us) if source.thrusters else None
        uuv_tel.name_depth_source(source.name)  # the word of a depth its source adds without one
        settings = registry.settings(source, u.parts.get(source.name, {}))
        sigma_m = cal.sigmas.depth_m
        depth = source.build(
            DepthInput(u, session, uuv_tel, depth_gate, sigma_m, thrusters, source.name, settings)
        )
        own.add(depth, INPUTS, "depth", is_input=True)
        if recorder:  # its part of the recording
            depth.listeners.append(recorder.on_depth)
        uuv_position = own.add(
            UuvPosition(
                session,
                u.uuv_position_key,
                cfg.uuv_prior_sigma_m,
                parse_hint(u.uuv_hint) if u.uuv_hint else None,
            ),
            INPUTS,
            "uuv_position",
        )
        gate = None  # the UUV's safety gates, for GPS_INPUT
        if u.gps_input:
            max_age_s = cfg.fix_max_age_ms / 1000.0
            gate = FixGate(
                max_speed_mps=cfg.uuv_max_speed_mps,
                max_accel_mps2=cfg.uuv_max_accel_mps2,
                max_h_acc_m=cfg.fix_max_h_acc_m,
                max_age_s=max_age_s,
                thrusters=thrusters,
                water_accel_mps2=cfg.uuv_water_accel_mps2,
                max_reach_m=cfg.uuv_max_reach_m,
                fleet=fleet,
                uuv_id=u.id,
            )
            if cfg.state_folder:  # the UUV's last trusted track, kept across restarts
                path = track_path(cfg.state_folder, u.id)
                keeper = TrackMemory(gate, path, remember(gate, path, cfg.track_max_age_s))
                own.add(keeper, OUTPUTS, "track_memory", lambda now: keeper.status())
        outputs = uuv_outputs(cfg, u, session, gate, own)
        fix_sink = next((o for o in outputs if isinstance(o, ZenohFixSink)), None)
        self.gps = gps = next((o for o in outputs if isinstance(o, GpsInputSink)), None)
        watchdog = Watchdog(
            lambda now: shared.inputs(now) | own.inputs(now),
            tuple(needed_rates(cal.mount.attitude_source)),
            zenoh_peers,
            require_s=REQUIRE_S if cfg.require_inputs else None,
        )
        feed, topview = page
        sinks = [s for s in (*outputs, recorder, feed, topview, watchdog) if s is not None]
        self.pipeline = pipeline = Pipeline(
            cal,
            tel,
            cfg.tracker,
            sinks,
            telemetry_wait_s=cfg.telemetry_wait_ms / 1000.0,
            prior=uuv_position.prior,
            history_s=cfg.select_history_s,
            on_tracked=on_tracked,
            alignment=alignment,
            vet=vet,
            tracking=tracking,
            poses=poses,
            depth=uuv_tel.depth,
            correct=correct,
        )
        own.add(pipeline, PIPELINE, "pipeline", lambda now: pipeline.status())
        own.section("target", lambda now: pipeline.target)

        def latest_fix() -> dict | None:
            """The last fix published on Zenoh (None without the output zenoh)."""
            return fix_sink.latest if fix_sink else None

        own.section("fixes_published", lambda now: fix_sink.published if fix_sink else 0)
        own.section("fix", lambda now: latest_fix())
        own.add(watchdog, PIPELINE, "problems", lambda now: dict(watchdog.problems))
        if gps:
            own.section("latency", lambda now: latency_summary(list(gps.latencies_s)[-1000:]))
        self.control = Control(pipeline, self.status, gps.gate.confirm if gps else None)
        status_sink = ZenohStatus(session, u.status_key, u.alive_key, self.status)
        self.zenoh_control = ZenohControl(
            session,
            self.control,
            u.control_prefix,
            {u.fix_key: latest_fix, u.status_key: lambda: status_sink.latest},
        )
        own.add(self.zenoh_control, INPUTS, "control", lambda now: self.zenoh_control.status())
        own.add(status_sink, OUTPUTS)

    def status(self, now: float) -> dict:
        """The UUV's status: the shared sections (the UAV, the video, the page) and its own."""
        return self._shared.status(now) | self.workers.status(now)

    def final(self, now: float, shared: bool = True) -> dict:
        """The status at the end (its own sections only unless ``shared``), with every latency measured."""
        out = self.status(now) if shared else self.workers.status(now)
        if self.gps:
            out["latency"] = latency_summary(self.gps.latencies_s)
            out["latencies_ms"] = [round(x * 1000.0, 3) for x in self.gps.latencies_s]
        return out


def run(cfg: config.RunConfig) -> int:
    """The service with ``cfg`` to its end: exit code 0 after a clean stop, 2 after an error (one line)."""
    logging.basicConfig(
        level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s: %(message)s"
    )
    final = run_to_end("run", serve(cfg), (OSError, zenoh.ZError, InputMissing), cfg.stats)
    if final is None:
        return 2
    log.info("stopped: %s", json.dumps({k: v for k, v in final.items() if k != "latencies_ms"}))
    return 0
