"""Live inputs of the service: the UAV's telemetry, the UUV's depth, the UAV's video."""
