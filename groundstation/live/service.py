"""``skyfix run``: the live service. One asyncio task per link, all in one TaskGroup.

Workers: the UAV's MAVLink (:mod:`.sources.uav_mavlink`), the UUV's depth (skyfix's JSON over
Zenoh, :mod:`.sources.depth_zenoh`, or ArduSub's own over BlueOS's Zenoh or MAVLink,
:mod:`.sources.depth_ardusub`), the UUV's own position estimate
(:mod:`.sources.uuv_position`), the UAV's video (:mod:`groundstation.video.live`),
the per-frame :mod:`.pipeline` (and the height from the UUV's size, :mod:`groundstation.height_from_size`),
GPS_INPUT to the UUV (:mod:`.sinks.gps_input`),
the 1 Hz Zenoh status (:mod:`.sinks.zenoh_fix`), the operator's commands
(:mod:`.control`), the web page (:mod:`.ui`, unless ``--no-ui``) and, with ``--record``,
the recorder (:mod:`.sinks.recorder`). The web page's port is taken before any worker
starts, so a port in use stops the service at once (exit 2). Blocking I/O lives in threads owned by the
workers (:mod:`groundstation.threads`: bounded hand-offs to the loop, supervised, never waited for at a stop);
all telemetry is written and read on the event loop.

The workers are declared in one registry (:mod:`.workers`): each with its stop stage, its
status section and whether the watchdog judges it as an input; the status is the
registry's. The pipeline is built with its sinks and frame listeners.

Stopping: SIGINT/SIGTERM (or ``--duration-s``) stop the workers in order — the inputs
(and the operator's commands and web page), then the pipeline, then the sinks — each stage
cancelled and awaited before the next (a stage slower than
:data:`~groundstation.live.workers.STAGE_S` is logged), and last the GPS_INPUT sink, whose
last message says "no fix". Nothing waits for a blocked read or open: the whole stop takes well under a second whatever the inputs are doing
(``bench/links.py`` measures it). A worker that fails cancels the others (the sink still
sends its no-fix) and the service exits with its error. The Zenoh session is closed in ``finally``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import signal
import time

import numpy as np
import zenoh

from groundstation.height_from_size import HeightFromSize, OnlineHeightFromSize
from groundstation.latency.estimate import OnlineLatency
from groundstation.live import config
from groundstation.live.control import Control, ZenohControl
from groundstation.live.pipeline import Pipeline
from groundstation.live.sinks.gps_input import GpsInputSink, mavlink_gps_link
from groundstation.live.sinks.recorder import Recorder
from groundstation.live.sinks.zenoh_fix import ZenohFixSink, ZenohStatus
from groundstation.live.sinks.zenoh_mavlink import ZenohMavlinkIn
from groundstation.live.sources.depth_ardusub import ArduSubMavlink, ArduSubZenoh
from groundstation.live.sources.depth_zenoh import DepthZenoh
from groundstation.live.sources.rates import needed_rates
from groundstation.live.sources.uav_mavlink import UavMavlink
from groundstation.live.sources.uuv_position import UuvPosition, parse_hint
from groundstation.live.ui.feed import VideoFeed
from groundstation.live.ui.server import WebUi, settings_of
from groundstation.live.ui.topview import TopView
from groundstation.live.usage import Usage
from groundstation.live.watchdog import REQUIRE_S, InputMissing, Watchdog
from groundstation.live.workers import INPUTS, LAST, OUTPUTS, PIPELINE, Workers, run_to_end, stopped
from groundstation.mavlink.link import read_signing_key
from groundstation.video.live import VideoLive
from groundstation.zenoh_session import open_session
from localizer.depth import DepthGate
from localizer.fix_gate import FixGate
from localizer.height import status as height_status
from localizer.telemetry import Telemetry
from localizer.thrusters import Thrusters

log = logging.getLogger("skyfix.run")

TELEMETRY_KEEP_S = 60.0


def latency_summary(latencies_s) -> dict:
    """Percentiles (ms) of frame arrival → GPS_INPUT sent; None when nothing was measured."""
    a = np.asarray(latencies_s, dtype=float) * 1000.0
    if len(a) == 0:
        return {"n": 0, "p50_ms": None, "p99_ms": None, "max_ms": None}
    return {"n": len(a), "p50_ms": round(float(np.percentile(a, 50)), 3),
            "p99_ms": round(float(np.percentile(a, 99)), 3), "max_ms": round(float(a.max()), 3)}


async def serve(cfg: config.RunConfig) -> dict:
    """Run the service until stopped; returns the final status."""
    loop = asyncio.get_running_loop()
    cal = config.load_calibration(cfg.calibration)
    tel = Telemetry(cal.timing, keep_s=TELEMETRY_KEEP_S)
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    session = open_session(cfg.zenoh_connect, cfg.zenoh_listen, multicast=cfg.zenoh_multicast,
                           config_file=cfg.zenoh_config)
    closers = []
    usage = Usage()
    try:
        size = (cal.camera.width, cal.camera.height)
        auto = cfg.video_latency_ms == "auto"
        fixed_latency_s = None if auto else cfg.video_latency_ms / 1000.0
        first_aligned: list[float] = []  # auto: the exposure of the first frame stamped with the estimate
        workers = Workers()
        pipeline: Pipeline  # built once its sinks and listeners are (below); the closures read it then

        # -- the inputs: the UAV, the UUV's depth (and thrusters), its own position, the video ----------------------
        if cfg.mavlink_backend == "mavsdk":
            from groundstation.live.sources.uav_mavsdk import UavMavsdk

            uav = UavMavsdk(cfg.mavlink, tel)
        else:
            uav = UavMavlink(cfg.mavlink, tel, needed_rates(cal.mount.attitude_source),
                             request_rates=not cfg.no_request_rates)
        uav.listeners.append(lambda *a: pipeline.telemetry_arrived(*a))
        workers.add(uav, INPUTS, "uav", is_input=True)
        depth_gate = DepthGate(cfg.uuv_max_vertical_speed_mps, cal.sigmas.depth_m)
        # the UUV's thrusters, read with its depth from ArduSub: the fix gate's second source of the UUV's motion
        thrusters = Thrusters(cfg.thruster_deadband_us) if cfg.depth_source in ("blueos", "mavlink") else None
        if cfg.depth_source == "mavlink":
            depth = ArduSubMavlink(cfg.depth_mavlink, tel, depth_gate, cal.sigmas.depth_m, thrusters=thrusters)
        elif cfg.depth_source == "blueos":
            depth = ArduSubZenoh(session, cfg.depth_input_key, tel, depth_gate, cal.sigmas.depth_m,
                                 thrusters=thrusters)
        else:
            depth = DepthZenoh(session, cfg.depth_input_key, tel, depth_gate)
        workers.add(depth, INPUTS, "depth", is_input=True)
        workers.section("height", lambda now: height_status(cal.water, cal.sigmas, tel))
        uuv_position = workers.add(UuvPosition(session, cfg.uuv_position_key, cfg.uuv_prior_sigma_m,
                                               parse_hint(cfg.uuv_hint) if cfg.uuv_hint else None),
                                   INPUTS, "uuv_position")
        video = motion = from_size = None
        if cfg.video:
            video = VideoLive(cfg.video, fixed_latency_s, lambda frame: pipeline.submit(frame), expected_size=size)
            motion = OnlineLatency(cal, tel, fixed_latency_s,
                                   (lambda s: setattr(video, "latency_s", s)) if auto else None)
            workers.add(video, INPUTS, "video", lambda now: video.status(now)
                        | {"latency_from_motion": motion.status()}, is_input=True)
            workers.add(motion, INPUTS)
            if cfg.height_from_size != "off":
                from_size = workers.add(OnlineHeightFromSize(HeightFromSize(cal, tel, cfg.height_from_size)), INPUTS,
                                        "height_from_size", lambda now: from_size.status())

        def recorded_timing() -> dict:
            """What the run measured and used for time, for the recording's [timing]."""
            measured = tel.measured_latency_s
            out = {"mavlink_latency_measured_s": None if measured is None else round(measured, 4),
                   "mavlink_latency_measured_from_t": tel.measured_latency_from_s}
            if video is None:
                return out
            if not auto:
                return out | {"video_latency_s": fixed_latency_s, "video_latency_source": "configured"}
            if motion.applied_s is None:
                return out
            return out | {"video_latency_s": round(motion.applied_s, 4), "video_latency_source": "motion",
                          "video_latency_sigma_s": round(motion.applied_sigma_s, 4),
                          "video_latency_from_t": first_aligned[0] if first_aligned else None}

        # -- the outputs: fixes on Zenoh, GPS_INPUT (through the gates), the recording, the watchdog, the page -----
        fix_sink = ZenohFixSink(session, cfg.fix_key)
        closers.append(fix_sink.close)
        gps = None
        if cfg.gps_input:
            key = read_signing_key(cfg.gps_input_signing_key) if cfg.gps_input_signing_key else None
            link = (ZenohMavlinkIn(session, cfg.gps_input.removeprefix("zenoh:")) if cfg.gps_input.startswith("zenoh:")
                    else mavlink_gps_link(cfg.gps_input, signing_key=key))
            max_age_s = cfg.fix_max_age_ms / 1000.0
            gate = FixGate(max_speed_mps=cfg.uuv_max_speed_mps, max_accel_mps2=cfg.uuv_max_accel_mps2,
                           max_h_acc_m=cfg.fix_max_h_acc_m, max_age_s=max_age_s, thrusters=thrusters,
                           water_accel_mps2=cfg.uuv_water_accel_mps2)
            gps = GpsInputSink(link, cfg.gps_input_hz, max_age_s, gate)
        recorder = None
        if cfg.record:
            recorder = Recorder(cfg.record, cfg.calibration, video_size=size if cfg.video else None,
                                timing=recorded_timing)
            uav.listeners.append(recorder.on_mavlink)
            depth.listeners.append(recorder.on_depth)
            workers.add(recorder, OUTPUTS, "record", lambda now: recorder.status(), is_input=True)

        def zenoh_peers() -> int:
            return len(list(session.info.peers_zid())) + len(list(session.info.routers_zid()))

        watchdog = Watchdog(workers.inputs, tuple(needed_rates(cal.mount.attitude_source)), zenoh_peers,
                            require_s=REQUIRE_S if cfg.require_inputs else None)
        topview = feed = None
        if not cfg.no_ui:
            topview = TopView(cal, tel)
            feed = VideoFeed(lambda: pipeline.target)

        def first_aligned_frame(frame) -> None:
            if frame.aligned and not first_aligned:
                first_aligned.append(frame.t_unix)

        frame_listeners = [f for f in (recorder and recorder.on_frame, feed and feed.on_frame,
                                       motion and motion.on_frame, motion and auto and first_aligned_frame) if f]
        sinks = [s for s in (fix_sink, gps, recorder, feed, topview, watchdog) if s is not None]
        pipeline = Pipeline(cal, tel, cfg.tracker, sinks, telemetry_wait_s=cfg.telemetry_wait_ms / 1000.0,
                            prior=uuv_position.prior, history_s=cfg.select_history_s, frame_listeners=frame_listeners,
                            on_tracked=[from_size.on_tracked] if from_size else [],
                            alignment=(lambda: ("motion", motion.applied_sigma_s)) if video and auto else None)
        if video and auto:
            log.info("--video-latency-ms auto: no valid fix until the video's latency from the image's motion "
                     "has settled (status latency_unsettled)")
        workers.add(pipeline, PIPELINE, "pipeline", lambda now: pipeline.status())
        workers.section("target", lambda now: pipeline.target)
        workers.section("fixes_published", lambda now: fix_sink.published)
        workers.section("fix", lambda now: fix_sink.latest)
        workers.add(watchdog, PIPELINE, "problems", lambda now: dict(watchdog.problems))
        workers.section("zenoh", lambda now: {"peers": zenoh_peers()})
        workers.section("process", usage.status)
        if gps:
            workers.add(gps, LAST, "gps_input")
            workers.section("latency", lambda now: latency_summary(list(gps.latencies_s)[-1000:]))

        # -- the operator's side: commands over Zenoh and the page ---------------------------------------------------
        control = Control(pipeline, workers.status)
        ui = WebUi(cfg.ui, cfg.ui_token, control, topview, feed, size, settings_of(cfg)) if feed else None
        status_sink = ZenohStatus(session, cfg.status_key, cfg.alive_key, workers.status)
        zenoh_control = ZenohControl(session, control, cfg.control_prefix,
                                     {cfg.fix_key: lambda: fix_sink.latest, cfg.status_key: lambda: status_sink.latest})
        workers.add(zenoh_control, INPUTS, "control", lambda now: zenoh_control.status())
        if ui:
            workers.add(ui, INPUTS, "ui", lambda now: ui.status())
        workers.add(status_sink, OUTPUTS)
        if ui:
            await ui.start()  # UiError (an OSError) when its port is taken: exit 2 before anything runs
        log.info("skyfix run: UAV %s, video %s, depth %s (%s), fixes on %s, GPS_INPUT %s, commands on %s/*",
                 cfg.mavlink, cfg.video, cfg.depth_mavlink or cfg.depth_input_key, cfg.depth_source, cfg.fix_key,
                 cfg.gps_input, zenoh_control.prefix)
        if cal.init_bbox is None:
            log.info("no tracker.init_bbox: awaiting a target (%s/select%s%s)", zenoh_control.prefix,
                     f", the web page {ui.url}" if ui else "",
                     ", or near the UUV's own position" if cfg.uuv_position_key or cfg.uuv_hint else "")
        await workers.run(stopped(stop, cfg.duration_s))
        final = workers.status(time.time())
        if gps:
            final["latency"] = latency_summary(gps.latencies_s)
            final["latencies_ms"] = [round(x * 1000.0, 3) for x in gps.latencies_s]
        return final
    finally:
        for close in closers:
            close()
        session.close()


def run(args: argparse.Namespace) -> int:
    """``skyfix run``: exit code 0 after a clean stop."""
    cfg = config.run_config(args)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s: %(message)s")
    final = run_to_end("run", serve(cfg), (OSError, zenoh.ZError, InputMissing), cfg.stats)
    if final is None:
        return 2
    log.info("stopped: %s", json.dumps({k: v for k, v in final.items() if k != "latencies_ms"}))
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "run", help="the live service: MAVLink, Zenoh and video in; fixes and GPS_INPUT out",
        usage="%(prog)s --calibration FILE [--config FILE] [options]",
        description="The live service: reads the UAV's MAVLink telemetry and video and the UUV's depth (Zenoh); "
                    "publishes each fix on Zenoh (--fix-key) and sends GPS_INPUT to the UUV's autopilot "
                    "(--gps-input); health on --status-key once a second. Stops on Ctrl-C or SIGTERM.",
        epilog="example: skyfix run --calibration cal.toml --mavlink udpin:0.0.0.0:14550 --video udp://0.0.0.0:5600 "
               "--zenoh-connect tcp/192.168.2.2:7447 --gps-input udpout:192.168.2.2:14660")
    config.add_arguments(p)
    p.set_defaults(func=run)

