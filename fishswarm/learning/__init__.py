"""Turing learning of fish behaviour: replicas and classifiers co-evolved with CMA-ES."""
