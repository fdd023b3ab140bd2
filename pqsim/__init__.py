"""pqsim."""
