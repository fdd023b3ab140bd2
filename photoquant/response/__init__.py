"""photoquant/response."""
