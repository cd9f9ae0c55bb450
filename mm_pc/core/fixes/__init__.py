"""Absolute fixes for fusion: wheels, GPS, the perimeter wire."""
