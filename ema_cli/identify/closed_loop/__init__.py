"""Output-error identification of the whole simulator from a closed-loop log: multiple shooting, GA
+ least squares."""
