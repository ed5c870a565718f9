"""Controllers from the companion papers (001, 002, 004) and beyond; one module each."""
