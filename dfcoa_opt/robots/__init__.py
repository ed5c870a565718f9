"""Batched kinematic robot models."""
