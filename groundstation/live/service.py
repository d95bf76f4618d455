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

Stopping: SIGINT/SIGTERM (or ``--duration-s``) stop the workers in order — the inputs
(and the operator's commands and web page), then the pipeline, then the sinks — each stage
cancelled and awaited before the next (a stage slower than :data:`STAGE_S` is logged), and
last the GPS_INPUT sink, whose last message says "no fix". Nothing waits for a blocked
read or open: the whole stop takes well under a second whatever the inputs are doing
(``bench/links.py`` measures it). A worker that fails cancels the others (the sink still
sends its no-fix) and the service exits with its error. The Zenoh session is closed in ``finally``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import signal
import sys
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
from groundstation.live.ui.server import WebUi, settings_of
from groundstation.live.ui.topview import TopView
from groundstation.live.usage import Usage
from groundstation.live.watchdog import REQUIRE_S, InputMissing, Watchdog
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
STAGE_S = 0.3  # a stage of the stop longer than this is logged


def latency_summary(latencies_s) -> dict:
    """Percentiles (ms) of frame arrival → GPS_INPUT sent; None when nothing was measured."""
    a = np.asarray(latencies_s, dtype=float) * 1000.0
    if len(a) == 0:
        return {"n": 0, "p50_ms": None, "p99_ms": None, "max_ms": None}
    return {"n": len(a), "p50_ms": round(float(np.percentile(a, 50)), 3),
            "p99_ms": round(float(np.percentile(a, 99)), 3), "max_ms": round(float(a.max()), 3)}


async def _stopper(stop: asyncio.Event, duration_s: float | None) -> None:
    try:
        await asyncio.wait_for(stop.wait(), timeout=duration_s)
    except TimeoutError:
        pass


async def _stop_in_order(stages: list[list[asyncio.Task]]) -> None:
    """Cancel each stage's tasks and wait for them before the next stage."""
    loop = asyncio.get_running_loop()
    for stage in stages:
        if not stage:
            continue
        t0 = loop.time()
        for task in stage:
            task.cancel()
        await asyncio.wait(stage)
        if loop.time() - t0 > STAGE_S:
            log.warning("stopping %s took %.2f s", ", ".join(t.get_name() for t in stage), loop.time() - t0)


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
        video = motion = None
        auto = cfg.video_latency_ms == "auto"
        first_aligned: list[float] = []  # auto: the exposure of the first frame stamped with the estimate

        def recorded_timing() -> dict:
            """What the run measured and used for time, for the recording's [timing]."""
            measured = tel.measured_latency_s
            out = {"mavlink_latency_measured_s": None if measured is None else round(measured, 4),
                   "mavlink_latency_measured_from_t": tel.measured_latency_from_s}
            if video is None:
                return out
            if not auto:
                return out | {"video_latency_s": cfg.video_latency_ms / 1000.0, "video_latency_source": "configured"}
            if motion.applied_s is None:
                return out
            return out | {"video_latency_s": round(motion.applied_s, 4), "video_latency_source": "motion",
                          "video_latency_sigma_s": round(motion.applied_sigma_s, 4),
                          "video_latency_from_t": first_aligned[0] if first_aligned else None}

        recorder = Recorder(cfg.record, cfg.calibration, video_size=size if cfg.video else None,
                            timing=recorded_timing) if cfg.record else None
        fix_sink = ZenohFixSink(session, cfg.fix_key)
        closers.append(fix_sink.close)
        sinks = [fix_sink]
        gps = None
        # the UUV's thrusters, read with its depth from ArduSub: the fix gate's second source of the UUV's motion
        thrusters = Thrusters(cfg.thruster_deadband_us) if cfg.depth_source in ("blueos", "mavlink") else None
        if cfg.gps_input:
            key = read_signing_key(cfg.gps_input_signing_key) if cfg.gps_input_signing_key else None
            link = (ZenohMavlinkIn(session, cfg.gps_input.removeprefix("zenoh:")) if cfg.gps_input.startswith("zenoh:")
                    else mavlink_gps_link(cfg.gps_input, signing_key=key))
            max_age_s = cfg.fix_max_age_ms / 1000.0
            gate = FixGate(max_speed_mps=cfg.uuv_max_speed_mps, max_accel_mps2=cfg.uuv_max_accel_mps2,
                           max_h_acc_m=cfg.fix_max_h_acc_m, max_age_s=max_age_s, thrusters=thrusters,
                           water_accel_mps2=cfg.uuv_water_accel_mps2)
            gps = GpsInputSink(link, cfg.gps_input_hz, max_age_s, gate)
            sinks.append(gps)
        if recorder:
            sinks.append(recorder)
        uuv_position = UuvPosition(session, cfg.uuv_position_key, cfg.uuv_prior_sigma_m,
                                   parse_hint(cfg.uuv_hint) if cfg.uuv_hint else None)
        pipeline = Pipeline(cal, tel, cfg.tracker, sinks, telemetry_wait_s=cfg.telemetry_wait_ms / 1000.0,
                            prior=uuv_position.prior, history_s=cfg.select_history_s)

        if cfg.mavlink_backend == "mavsdk":
            from groundstation.live.sources.uav_mavsdk import UavMavsdk

            uav = UavMavsdk(cfg.mavlink, tel)
        else:
            uav = UavMavlink(cfg.mavlink, tel, needed_rates(cal.mount.attitude_source),
                             request_rates=not cfg.no_request_rates)
        uav.listeners.append(pipeline.telemetry_arrived)
        depth_key = cfg.depth_input_key
        gate = DepthGate(cfg.uuv_max_vertical_speed_mps, cal.sigmas.depth_m)
        if cfg.depth_source == "mavlink":
            depth = ArduSubMavlink(cfg.depth_mavlink, tel, gate, cal.sigmas.depth_m, thrusters=thrusters)
        elif cfg.depth_source == "blueos":
            depth = ArduSubZenoh(session, depth_key, tel, gate, cal.sigmas.depth_m, thrusters=thrusters)
        else:
            depth = DepthZenoh(session, depth_key, tel, gate)
        control = Control(pipeline, lambda now: status(now))
        ui = None
        if not cfg.no_ui:
            topview = TopView(cal, tel)
            ui = WebUi(cfg.ui, cfg.ui_token, control, topview, size, settings_of(cfg))
            pipeline.sinks += [ui.feed, topview]
        from_size = None
        if cfg.video:
            frame_listeners = [listener.on_frame for listener in (recorder, ui and ui.feed) if listener]

            def submit(frame):
                if frame.aligned and auto and not first_aligned:
                    first_aligned.append(frame.t_unix)
                for listener in frame_listeners:
                    listener(frame)
                pipeline.submit(frame)
            video = VideoLive(cfg.video, None if auto else cfg.video_latency_ms / 1000.0, submit, expected_size=size)

            def apply(latency_s: float) -> None:
                video.latency_s = latency_s

            motion = OnlineLatency(cal, tel, None if auto else video.latency_s, apply if auto else None)
            frame_listeners.append(motion.on_frame)
            if auto:
                pipeline.alignment = lambda: ("motion", motion.applied_sigma_s)
                log.info("--video-latency-ms auto: no valid fix until the video's latency from the image's motion "
                         "has settled (status latency_unsettled)")
            if cfg.height_from_size != "off":
                from_size = OnlineHeightFromSize(HeightFromSize(cal, tel, cfg.height_from_size))
                pipeline.on_tracked.append(from_size.on_tracked)
        if recorder:
            uav.listeners.append(recorder.on_mavlink)
            depth.listeners.append(recorder.on_depth)

        def inputs(now: float) -> dict:
            out = {"uav": uav.status(now), "depth": depth.status(now)}
            if video:
                out["video"] = video.status(now)
            if recorder:
                out["record"] = recorder.status()
            return out

        def zenoh_peers() -> int:
            return len(list(session.info.peers_zid())) + len(list(session.info.routers_zid()))

        watchdog = Watchdog(inputs, tuple(needed_rates(cal.mount.attitude_source)), zenoh_peers,
                            require_s=REQUIRE_S if cfg.require_inputs else None)
        pipeline.sinks.append(watchdog)

        def status(now: float) -> dict:
            out = {"uav": uav.status(now), "depth": depth.status(now), "height": height_status(cal.water, cal.sigmas, tel),
                   "pipeline": pipeline.status(),
                   "target": pipeline.target, "uuv_position": uuv_position.status(now),
                   "fixes_published": fix_sink.published, "fix": fix_sink.latest, "control": zenoh_control.status(),
                   "problems": dict(watchdog.problems), "zenoh": {"peers": zenoh_peers()},
                   "process": usage.status(now)}
            if video:
                out["video"] = video.status(now) | {"latency_from_motion": motion.status()}
            if from_size:
                out["height_from_size"] = from_size.status()
            if gps:
                out["gps_input"] = gps.status(now)
                out["latency"] = latency_summary(list(gps.latencies_s)[-1000:])
            if recorder:
                out["record"] = recorder.status()
            if ui:
                out["ui"] = ui.status()
            return out

        status_sink = ZenohStatus(session, cfg.status_key, cfg.alive_key, status)
        zenoh_control = ZenohControl(session, control, cfg.control_prefix,
                                     {cfg.fix_key: lambda: fix_sink.latest, cfg.status_key: lambda: status_sink.latest})
        # the order of the stop: inputs (and the operator's side), the pipeline, the sinks; GPS_INPUT last
        stages = [[w for w in (uav, depth, uuv_position, video, motion, from_size, zenoh_control, ui) if w is not None],
                  [pipeline, watchdog], [w for w in (status_sink, recorder) if w is not None]]
        workers = [w for stage in stages for w in stage] + ([gps] if gps else [])
        if ui:
            await ui.start()  # UiError (an OSError) when its port is taken: exit 2 before anything runs
        log.info("skyfix run: UAV %s, video %s, depth %s (%s), fixes on %s, GPS_INPUT %s, commands on %s/*",
                 cfg.mavlink, cfg.video, cfg.depth_mavlink or depth_key, cfg.depth_source, cfg.fix_key, cfg.gps_input,
                 zenoh_control.prefix)
        if cal.init_bbox is None:
            log.info("no tracker.init_bbox: awaiting a target (%s/select%s%s)", zenoh_control.prefix,
                     f", the web page {ui.url}" if ui else "",
                     ", or near the UUV's own position" if cfg.uuv_position_key or cfg.uuv_hint else "")
        async with asyncio.TaskGroup() as tg:
            tasks = {w: tg.create_task(w.run(), name=type(w).__name__) for w in workers}
            await _stopper(stop, cfg.duration_s)
            log.info("stopping")
            await _stop_in_order([[tasks[w] for w in stage] for stage in stages])
            if gps:  # last, once nothing feeds it: a no-fix GPS_INPUT, then its link closed
                await gps.stop()
        final = status(time.time())
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
    final = None
    try:
        final = asyncio.run(serve(cfg))
    except* (OSError, zenoh.ZError, InputMissing) as eg:  # a link that cannot be opened: one line each
        for e in eg.exceptions:
            print(f"skyfix run: error: {e}", file=sys.stderr)
    if final is None:
        return 2
    if cfg.stats:
        with open(cfg.stats, "w") as f:
            json.dump(final, f, indent=1)
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

