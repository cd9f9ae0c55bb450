"""Maps: the coverage grid and beacon trilateration."""
