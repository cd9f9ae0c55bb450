"""Absolute fixes for fusion: wheels, GPS, NMEA, the perimeter wire."""
