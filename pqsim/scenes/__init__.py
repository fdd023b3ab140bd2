"""pqsim/scenes."""
