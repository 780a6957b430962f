"""Benchmarks: speed, memory and accuracy, measured against peers in the same run (`make bench`)."""
