"""Optimisers shared by identification and tuning: the project's genetic algorithms (the paper's
binary GA and the improved real-coded elitist GA, :mod:`ema_cli.optim.ga`) and a budgeted
wrapper of scipy's differential evolution (:mod:`ema_cli.optim.de`). They know nothing of the
model: they minimise a batched cost over box bounds."""
