"""Identification from torque data: the transmission's stiffness and backlash (paper Eq. 8)."""
