"""Measuring the model: metrics, evaluations, benchmarks, plots and the demo pipeline."""
