"""`ema duty`: a mission profile through the actuator -> winding temperature, RMS current and
torque, life and a verdict (multirate: the mechanics per distinct segment, the thermal network
exactly over hours)."""
