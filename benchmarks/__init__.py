"""On-demand benchmarks of photoquant against its peers (``python -m benchmarks.run``); never run by the tests."""
