"""Identification of a rigid axis from a measured record by its inverse dynamic model (IDIM-LS,
the EMPS benchmark's method): MATLAB's filters emulated (``matlab``), the terms of the law
(``terms``), records and their checks (``records``), the estimator (``idim``) and the
benchmark's figures of merit (``benchmark``)."""
