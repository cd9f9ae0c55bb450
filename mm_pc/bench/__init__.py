"""mm-bench's pose, maps and gui benchmarks."""
