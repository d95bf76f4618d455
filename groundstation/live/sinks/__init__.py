"""Live outputs of the service. Each sink has ``on_fix(fix, frame_info)``, called on the event loop."""
