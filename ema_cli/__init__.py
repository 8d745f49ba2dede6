"""ema: experiment runner for the nonlinear analysis of electromechanical actuators."""

__version__ = "0.1.0"
