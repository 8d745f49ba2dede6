"""An independent generator of closed-loop EMA logs (issue 21's test battery).

A second simulator of the equations of docs/model.md §1-§2, written apart from ema's numba
kernel (nothing here imports ``ema_cli``): scipy ``solve_ivp`` (Radau) on the continuous
closed loop, three contact laws for the backlash (``jump``, ``ramp``, the foreign
``hunt_crossley``), analytic position commands (``chirp``, ``multisine``, ``steps``), and the
battery of logs with their truths (``python -m experiments.loggen.battery``).
"""
