"""Production yield (``ema yield``): manufacturing tolerances and wear as sampled laws over
run-config paths, the units drawn from them, and exact confidence intervals on the yield."""
