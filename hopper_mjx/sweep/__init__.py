"""Gravity and gain sweeps of the Raibert-controlled monoped: grid -> chunked runs -> report."""
