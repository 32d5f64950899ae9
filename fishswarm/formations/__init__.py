"""Formations: target maps, local shapes, the study's slot rules, formation flags, metrics."""
