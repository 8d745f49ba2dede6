"""Identification of the transmission stiffness and backlash: data, problem, GA, exact solver."""
