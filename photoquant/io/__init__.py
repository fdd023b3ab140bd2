"""photoquant/io."""
