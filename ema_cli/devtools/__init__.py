"""Developer checks run by the Makefile (not commands of ``ema``)."""
