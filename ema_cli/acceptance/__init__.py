"""The actuator acceptance battery (`ema acceptance`)."""
