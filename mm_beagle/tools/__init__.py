"""Tools around the node: the test/demo harness, benches, mm-watch, the demo, a link proxy."""
