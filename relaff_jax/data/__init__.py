"""Datasets: chunked, resumable, balanced stores of labelled rollouts and their features."""
