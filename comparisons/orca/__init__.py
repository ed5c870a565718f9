"""ORCA and the improved velocity obstacle of paper 001: lines, exact solver, filter."""
