"""Scenario schema and loader, simulator loop, virtual leader, run log."""
