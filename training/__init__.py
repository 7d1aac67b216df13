"""Offline training (PyTorch): datasets, networks, losses, loops, evaluation."""
