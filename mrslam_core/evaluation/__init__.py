"""Evaluation: trajectory errors, TUM files, plots and the run report."""
