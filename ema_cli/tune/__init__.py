"""Tuning of the controller and its compensators over scenarios (`ema tune`)."""
