"""Friction laws from constant-speed sweeps."""
