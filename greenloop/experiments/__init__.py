"""Experiments: one module per notebook's study; each function returns one table's unrounded DataFrame."""
