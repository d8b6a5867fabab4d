"""Offline identification of the model parameters."""
