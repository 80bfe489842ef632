"""Evaluation harness: metrics, datasets, the Hydra app (`python -m eval`)."""
