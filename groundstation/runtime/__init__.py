"""What the live service (``skyfix run``) and the fuser (``skyfix fuse``) both run on: the workers' runtime (their
stop stages and status, :mod:`.workers`), the process's own usage (:mod:`.usage`), fixes and status on Zenoh
(:mod:`.zenoh_fix`), MAVLink into BlueOS's Zenoh (:mod:`.zenoh_mavlink`), the Zenoh queryables of the
operator's commands and the late joiners (:mod:`.queries`), GPS_INPUT to the UUV's autopilot (:mod:`.gps_input`,
its no-fix words :mod:`.no_fix`), the start's checks both make (:mod:`.preflight`) and the parts by name
(:mod:`.parts`; the outputs both build: :mod:`.outputs`)."""
