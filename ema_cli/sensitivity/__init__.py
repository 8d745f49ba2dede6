"""Global sensitivity analysis (SALib): sampling the factor space, running every sample through
the sweep machinery, and the Morris and Sobol indices with their convergence."""
